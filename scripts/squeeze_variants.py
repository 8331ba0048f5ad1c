"""Write the squeeze variants (issue 29): tests/data/squeeze/variants/*.json and manifest.json.

A second set of squeeze scenes, made apart from ``rbe_ros.generators.squeeze`` the way a
held-out suite differs from ours: other proportions (0.4 m deep, other block sizes, bar
heights and post angles), mu near each limit, copies turned 90 deg about the vertical, and
compas_cra's type-b turned 90 deg about y as its example turns it (when its samples are
there: ``$RBE_COMPAS_SAMPLES``). The manifest gives each its mu and a closed-form verdict
where one exists (else null) and why; tests/test_squeeze_suite.py holds rbe_ros to
LMGC90's verdicts (``--lmgc90``: run them with the project's driver, rbe_ros/io/lmgc90.py,
the settings of ``make bench-lmgc90``, 1 s and 2 s, into lmgc90_verdicts.json beside them).
Deterministic: run it again and the scenes and manifest do not change.

    python scripts/squeeze_variants.py [--out tests/data/squeeze/variants] [--lmgc90]
    python scripts/squeeze_variants.py --table tests/data/squeeze[/variants]   # BENCHMARKS.md
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rbe_ros.generators import _box, _mirror, _xz_prism, squeeze  # noqa: E402
from rbe_ros.io.scene_json import scene_to_dict  # noqa: E402
from rbe_ros.scene import make_scene, turned  # noqa: E402

OUT = ROOT / "tests" / "data" / "squeeze" / "variants"
DEPTH = 0.4                 # m along y (the suite's: 0.3)
DENSITY = 2000.0
NO_PRELOAD = ("no load makes a normal force on the vertical faces (rigid blocks set one by one"
              " carry no pre-load): falls for any mu")


def _scene(name: str, parts) -> object:
    """A scene on a 4 x 0.8 m ground of prisms over (x, z) quads: parts (id, quad, support,
    mirrored pair)."""
    blocks = [_box("ground", (-2.0, -DEPTH, -0.25), (2.0, DEPTH, 0.0), density=DENSITY,
                   support=True)]
    for block_id, quad, support, both in parts:
        pairs = ((f"{block_id}_l", quad), (f"{block_id}_r", _mirror(quad))) if both else \
            ((block_id, quad),)
        blocks += [_xz_prism(i, q, DEPTH, density=DENSITY, support=support) for i, q in pairs]
    return make_scene(name, blocks, sequence=[b.id for b in blocks if not b.support])


def pillars(width=0.35, height=1.3, gap=0.6, z0=0.9, thick=0.25):
    """A bar between two free pillars, touching only their vertical faces."""
    a = gap / 2
    return _scene("pillars", [
        ("pillar", [(-a - width, 0), (-a, 0), (-a, height), (-a - width, height)], False, True),
        ("bar", [(-a, z0), (a, z0), (a, z0 + thick), (-a, z0 + thick)], False, False)])


def posts(angle_deg, gap=0.5, z0=0.6, thick=0.3):
    """A bar between fixed posts whose faces lean ``angle_deg`` (> 0: narrowing downward)."""
    t = math.tan(math.radians(angle_deg))

    def face(z):
        return -gap / 2 - (z - z0) * t
    return _scene("posts", [
        ("post", [(-1.0, 0), (face(0), 0), (face(1.1), 1.1), (-1.0, 1.1)], True, True),
        ("bar", [(face(z0), z0), (-face(z0), z0), (-face(z0 + thick), z0 + thick),
                 (face(z0 + thick), z0 + thick)], False, False)])


def leaning(angle_deg, foot=0.25, height=1.2, x0=-0.5, z0=0.8, thick=0.15):
    """Free posts of parallelogram section leaning inwards on a bar; with the statics limit
    without pre-load: each post tips about its inner foot edge O (on the line of its inner
    face), so only the bar's normal force N has a moment about O, N = W_post arm / s (s from O
    along the face, at least z0 / cos: N at its largest); the bar hangs on both faces,
    2 (F cos - N sin) = W_bar: a field without pre-load needs mu >= F / N (inf when the posts'
    centroid is over their foot: they press nothing)."""
    t = math.tan(math.radians(angle_deg))

    def face(z):
        return x0 + z * t
    scene = _scene("leaning", [
        ("post", [(x0 - foot, 0), (x0, 0), (face(height), height),
                  (face(height) - foot, height)], False, True),
        ("bar", [(face(z0), z0), (-face(z0), z0), (-face(z0 + thick), z0 + thick),
                 (face(z0 + thick), z0 + thick)], False, False)])
    a = math.radians(angle_deg)
    arm = height / 2 * t - foot / 2
    if arm <= 0:
        return scene, math.inf
    bar = thick * (-face(z0) - face(z0 + thick))                   # trapezoid area
    normal = foot * height * arm / (z0 / math.cos(a))
    return scene, (bar / 2 + normal * math.sin(a)) / math.cos(a) / normal


def flat_arch(n=3, width=0.25, z0=0.5, thick=0.3):
    """``n`` blocks with vertical joints between fixed abutments."""
    half = n * width / 2
    parts = [("abut", [(-half - 0.5, 0), (-half, 0), (-half, z0 + thick),
                       (-half - 0.5, z0 + thick)], True, True)]
    for k in range(n):
        a = -half + k * width
        parts.append((f"v{k}", [(a, z0), (a + width, z0), (a + width, z0 + thick),
                                (a, z0 + thick)], False, False))
    return _scene("flat-arch", parts)


def wedged_arch(angle_deg, n=3, width=0.25, z0=0.5, thick=0.3):
    """The same with joints through one point below, the outer ones ``angle_deg`` from
    vertical."""
    half = n * width / 2
    zc = z0 - half / math.tan(math.radians(angle_deg))

    def joint(xb, z):
        return xb * (z - zc) / (z0 - zc)
    parts = [("abut", [(-half - 0.6, 0), (joint(-half, 0), 0), (joint(-half, z0 + thick),
                                                                  z0 + thick),
                       (-half - 0.6, z0 + thick)], True, True)]
    for k in range(n):
        a, b = -half + k * width, -half + (k + 1) * width
        parts.append((f"v{k}", [(joint(a, z0), z0), (joint(b, z0), z0),
                                (joint(b, z0 + thick), z0 + thick),
                                (joint(a, z0 + thick), z0 + thick)], False, False))
    return _scene("wedged-arch", parts)


def incline(angle_deg, length=0.4, thick=0.15, bar="fixed", bar_length=1.0, bar_thick=0.12):
    """A block on a fixed ramp, under a bar lying on it parallel to the ramp (``bar``:
    "fixed", "free", or None)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    t = s / c
    base = 0.15 + t

    def at(u, v):
        return (u * c - v * s, base + u * s + v * c)
    parts = [("ramp", [(-1.0, 0), (1.0, 0), (1.0, base + t), (-1.0, base - t)], True, False),
             ("block", [at(-length / 2, 0), at(length / 2, 0), at(length / 2, thick),
                        at(-length / 2, thick)], False, False)]
    if bar:
        h = bar_length / 2
        parts.append(("bar", [at(-h, thick), at(h, thick), at(h, thick + bar_thick),
                              at(-h, thick + bar_thick)], bar == "fixed", False))
    return _scene("incline", parts)


def cantilever(overhang, length=1.2, thick=0.2, top=0.35):
    """A beam on a fixed pier, ``overhang`` beyond its edge, a block on its inner end; stands
    iff the weights' moment about the edge holds it down."""
    inner = overhang - length
    scene = _scene("cantilever", [
        ("pier", [(-1.5, 0), (0, 0), (0, 0.6), (-1.5, 0.6)], True, False),
        ("beam", [(inner, 0.6), (overhang, 0.6), (overhang, 0.6 + thick),
                  (inner, 0.6 + thick)], False, False),
        ("top", [(inner, 0.6 + thick), (inner + top, 0.6 + thick),
                 (inner + top, 0.6 + thick + top), (inner, 0.6 + thick + top)], False, False)])
    return scene, length * thick * (overhang - length / 2) + top * top * (inner + top / 2) <= 0


def shelf(length, corbel=0.2, thick=0.1, top_width=0.2, top_height=0.5):
    """A board against a fixed wall on a fixed corbel, a block on it over the corbel; the
    wall's face carries nothing without pre-load: stands iff the weights' moment about the
    corbel's edge holds the board down."""
    z = 0.75 + thick
    scene = _scene("shelf", [
        ("wall", [(-0.4, 0), (0, 0), (0, 1.5), (-0.4, 1.5)], True, False),
        ("corbel", [(0, 0.6), (corbel, 0.6), (corbel, 0.75), (0, 0.75)], True, False),
        ("board", [(0, 0.75), (length, 0.75), (length, z), (0, z)], False, False),
        ("top", [(0, z), (top_width, z), (top_width, z + top_height), (0, z + top_height)],
         False, False)])
    moment = length * thick * (length / 2 - corbel) + top_width * top_height * (
        top_width / 2 - corbel)
    return scene, moment <= 0


def tower(shift=0.0, n=4, width=0.4, height=0.25):
    """``n`` blocks, each ``shift`` along x from the one below: the blocks above the first
    joint have their centroid (n / 2) shift beyond the bottom block's centre, the worst
    joint: stands iff (n / 2) shift <= width / 2."""
    return _scene("tower", [(f"t{k}", [(k * shift - width / 2, k * height),
                                       (k * shift + width / 2, k * height),
                                       (k * shift + width / 2, (k + 1) * height),
                                       (k * shift - width / 2, (k + 1) * height)], False, False)
                            for k in range(n)])


def _yaw(scene, degrees: float):
    return turned(scene, Rotation.from_euler("z", degrees, degrees=True))


def _stands(ok: bool) -> str:
    return "stands" if ok else "falls"


def suite(samples: Path | None = None) -> list[dict]:
    """The variants: name, kind, mu, scene, closed-form verdict (or None) and why."""
    out = []

    def add(name, kind, scene, mus, closed, why):
        for mu in mus:
            verdict, reason = closed(mu) if callable(closed) else (closed, why)
            out.append({"name": f"{name}_mu{mu:.2f}", "kind": kind, "mu": mu, "scene": scene,
                        "closed_form": verdict, "why": reason})

    bar = pillars()
    add("v_pillars", "pillars", bar, (0.6, 0.84), "falls", "a bar between free pillars: "
        + NO_PRELOAD)
    add("v_pillars_yaw90", "pillars", _yaw(bar, 90.0), (0.84,), "falls",
        "the same turned 90 deg about the vertical: " + NO_PRELOAD)
    add("v_pillars_stub", "pillars", pillars(0.5, 0.6, 0.3, 0.3, 0.3), (0.84, 2.0), "falls",
        "a cube-like bar flush with the tops of short wide pillars: " + NO_PRELOAD)
    add("v_posts", "posts", posts(0.0), (0.84,), "falls", "a bar between fixed vertical posts: "
        + NO_PRELOAD)
    add("v_wedge6", "posts", posts(6.0), (0.3,), "stands",
        "a keystone whose faces narrow downward (6 deg): normal forces W / (2 sin 6 deg) carry"
        " it without friction, stands for any mu")
    for angle, mus in ((10.0, (0.6, 2.0, 6.0)), (20.0, (0.6, 1.0, 1.3, 1.6, 3.0))):
        scene, limit = leaning(angle)

        def closed(mu, angle=angle, limit=limit):
            if mu < limit:
                return "falls", (f"free posts leaning {angle:g} deg on a bar: their weight alone"
                                 f" presses it (no pre-load), a field needs mu >= {limit:.3f}"
                                 f" (inf: the posts' centroid is over their foot)")
            return None, (f"free posts leaning {angle:g} deg: a field without pre-load exists"
                          f" (mu >= {limit:.3f}), but whether the falling posts wedge the bar"
                          f" is dynamics (LMGC90 falls at 1.6, stands at 3)")
        add(f"v_leaning{angle:.0f}", "leaning-posts", scene, mus, closed, None)
    add("v_leaning_posts15", "leaning-posts", squeeze("leaning-posts", angle_deg=15.0),
        (3.0, 4.0), lambda mu: ("falls" if mu < 4.0 else None, (
            "the suite's leaning_posts15 at other mu: statics without pre-load needs mu >="
            " 4.367; LMGC90 wedges the bar at 4 (below it), not at 3")), None)
    arch = flat_arch()
    locked = ("blocks with vertical joints between fixed abutments: no load makes a normal"
              " force on a vertical joint and they slide down together without turning:"
              " falls for any mu")
    add("v_flat_arch", "flat-arch", arch, (0.84, 1.2), "falls", locked)
    add("v_flat_arch_yaw90", "flat-arch", _yaw(arch, 90.0), (1.2,), "falls", locked)
    add("v_flat_arch4", "flat-arch", flat_arch(4, 0.2, 0.5, 0.25), (1.2,), "falls", locked)
    add("v_wedged_arch20", "wedged-arch", wedged_arch(20.0), (0.6,), None,
        "joints through one point below, the outer ones 20 deg from vertical: no closed form")
    for angle, kwargs, mus in ((30.0, {}, (0.2, 0.5, 0.53, 0.55, 0.57, 0.62)),
                               (25.0, {"length": 0.3, "thick": 0.2}, (0.44, 0.5))):
        tan = math.tan(math.radians(angle))
        add(f"v_incline_pressed{angle:.0f}", "incline-pressed", incline(angle, **kwargs), mus,
            lambda mu, tan=tan, angle=angle: (_stands(mu >= tan), (
                f"a block on a {angle:.0f} deg ramp under a fixed bar lying on it: the bar gives"
                f" no normal force without pre-load, stands iff mu >= tan {angle:.0f} deg ="
                f" {tan:.4f}")), None)
    tan30 = math.tan(math.radians(30.0))
    add("v_incline_pressed30_yaw90", "incline-pressed", _yaw(incline(30.0), 90.0), (0.5,),
        "falls", f"turned 90 deg about the vertical: stands iff mu >= tan 30 deg = {tan30:.4f}")
    add("v_incline_pressed30_suite", "incline-pressed", squeeze("incline-pressed",
                                                                angle_deg=30.0), (0.55,),
        "falls", f"the suite's incline_pressed30 at mu 0.55: stands iff mu >= {tan30:.4f}")
    tan40 = math.tan(math.radians(40.0))
    add("v_incline_pressed40_suite", "incline-pressed", squeeze("incline-pressed",
                                                                angle_deg=40.0), (0.78, 0.81),
        "falls", f"the suite's incline_pressed40 near its limit: stands iff mu >= {tan40:.4f}")
    for angle, mus in ((50.0, (1.042,)), (60.0, (1.25, 1.354))):
        add(f"v_incline_pressed{angle:.0f}_suite", "incline-pressed",
            squeeze("incline-pressed", angle_deg=angle), mus, None,
            f"the suite's pressed incline at {angle:.0f} deg below tan: the base friction's"
            f" moment nearly tips the block (0.3 x 0.2) into the bar, whose normal force the"
            f" load then makes; no closed form")
    add("v_incline30", "incline", incline(30.0, bar=None), (0.55,), "falls",
        f"the block alone on the ramp: stands iff mu >= tan 30 deg = {tan30:.4f}")
    add("v_incline_freebar30", "incline", incline(30.0, bar="free", bar_length=0.4),
        (0.5, 0.62), lambda mu: (_stands(mu >= tan30), (
            f"a free bar lying on the block: both on the ramp, stands iff mu >= {tan30:.4f}")),
        None)
    for name, overhang in (("v_cantilever", 0.6), ("v_cantilever_far", 0.8)):
        scene, ok = cantilever(overhang)
        add(name, "cantilever", scene, (0.6,), _stands(ok),
            "tips about the pier's edge unless the weights' moment holds the beam down")
    for name, length, mus in (("v_shelf50", 0.5, (0.6,)), ("v_shelf75", 0.75, (0.6, 4.5, 8.0))):
        scene, ok = shelf(length)
        add(name, "shelf", scene, mus, _stands(ok),
            "tips about the corbel's edge unless the weights' moment holds the board down (the"
            " wall's face carries nothing without pre-load: no mu holds it)")
    add("v_shelf60_suite", "shelf", squeeze("shelf", overhang=0.6), (3.0, 5.0, 10.0, 13.0),
        "falls", "the suite's shelf60 at large mu: the wall's face carries nothing without"
        " pre-load (LMGC90 jams it from mu 13: a squeeze through the corbel's friction)")
    add("v_tower", "tower", tower(), (0.1,), "stands", "vertical loads only: stands for any mu")
    for name, shift in (("v_tower_lean", 0.09), ("v_tower_lean_far", 0.11)):
        add(name, "tower", tower(shift), (0.6,), _stands(2 * shift <= 0.2),
            "four blocks 0.4 wide, each shifted: stands iff 2 x shift <= 0.2")
    if samples is not None:
        from rbe_ros.io.compas import load_compas_assembly
        type_b = load_compas_assembly(samples / "type-b.json", supports=["0", "1"],
                                      density=DENSITY)
        for degrees, mus in ((90.0, (0.5, 0.55, 0.6, 0.7, 0.84)), (-90.0, (0.6,))):
            turn = Rotation.from_euler("y", degrees, degrees=True)
            add(f"v_type_b_roty{degrees:+.0f}", "type-b", turned(type_b, turn), mus, None,
                "compas_cra's type-b turned 90 deg about y as its example turns it: the load's"
                " moment presses the upper face (LMGC90 and cra_solve stand at 0.6-0.84)")
    return out


def write(out_dir: Path, samples: Path | None = None) -> list[dict]:
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = suite(samples)
    for e in entries:
        data = scene_to_dict(e.pop("scene"))
        data["name"] = e["name"]
        e["file"] = f"{e['name']}.json"
        (out_dir / e["file"]).write_text(json.dumps(data) + "\n")
    manifest = {"source": "scripts/squeeze_variants.py",
                "closed_form": "stands, falls, or null where no closed form decides",
                "scenes": entries}
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return entries


def run_lmgc90(out_dir: Path) -> dict:
    """LMGC90's verdict on every variant, 1 s and 2 s (lmgc90_verdicts.json), as make
    bench-lmgc90 decides it (rbe_ros.io.lmgc90.check); a variant with a verdict there at
    its mu and the same settings keeps it."""
    from rbe_ros.io import lmgc90
    from rbe_ros.io.scene_json import load_scene
    from rbe_ros.scene import gravity_down
    python = lmgc90.installed_python()

    def word(res):
        return "failed" if res.get("failed") else ("stands" if res["stable"] else "falls")
    done = out_dir / "lmgc90_verdicts.json"
    before = json.loads(done.read_text()) if done.exists() else {}
    scenes, versions = {}, before.get("versions", {})
    for e in json.loads((out_dir / "manifest.json").read_text())["scenes"]:
        kept = before.get("scenes", {}).get(e["name"])
        if kept and kept["mu"] == e["mu"] and before.get("settings") == lmgc90.settings():
            scenes[e["name"]] = kept | {"closed_form": e["closed_form"]}
            continue
        scene = gravity_down(load_scene(out_dir / e["file"]))
        res = lmgc90.check(scene, e["mu"], python)
        longer = lmgc90.check(scene, e["mu"], python, T=2 * lmgc90.T)
        versions = res.get("versions") or versions
        scenes[e["name"]] = {"mu": e["mu"], "closed_form": e["closed_form"], "lmgc90": word(res),
                             "lmgc90_2T": word(longer)} | {
            k: res.get(k) for k in ("stable", "moved", "max_disp", "max_rot_deg", "simulated",
                                    "time_process")}
        print(f"[lmgc90] {e['name']}: LMGC90 {word(res)} ({word(longer)} at 2 s)", flush=True)
    return {"source": "scripts/squeeze_variants.py --lmgc90 (rbe_ros.io.lmgc90.check as make"
                      " bench-lmgc90 runs it); docs/BENCHMARKS.md section 4 says how a verdict"
                      " is decided",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "versions": versions,
            "settings": lmgc90.settings(), "scenes": scenes} | (
        {"decides": before["decides"]} if "decides" in before else {})


def table(folder: Path) -> list[str]:
    """docs/BENCHMARKS.md's table of a squeeze folder (its manifest and LMGC90's verdicts):
    closed form, LMGC90, its largest motion, whether LMGC90 decides (the verdict the same
    under every setting of benchmarks/lmgc90_sensitivity.py, else the settings that differ),
    and this tree's check (default options; marked only where LMGC90 decides)."""
    from dataclasses import replace

    from rbe_ros.analysis.options import CheckOptions
    from rbe_ros.analysis.pipeline import check_scene
    from rbe_ros.io.scene_json import load_scene
    from rbe_ros.rbe.solver import SolveOptions
    verdicts = json.loads((folder / "lmgc90_verdicts.json").read_text())["scenes"]
    lines = ["| scene | mu | closed form | LMGC90 | largest motion (x size, deg) | moved |"
             " LMGC90 decides | rbe_ros |", "|---|---|---|---|---|---|---|---|"]
    for e in json.loads((folder / "manifest.json").read_text())["scenes"]:
        r = verdicts[e["name"]]
        report = check_scene(load_scene(folder / e["file"]),
                             replace(CheckOptions(), solve=SolveOptions(mu=e["mu"])))
        runs = r.get("sensitivity") or {}
        other = [f"{s} {v}" for s, v in runs.items() if v != r["lmgc90"]]
        decides = "-" if not runs else (f"yes ({len(runs)})" if r["decides"] else
                                        "no: " + ", ".join(other or ["creeps"]))
        mark = "" if not r.get("decides", True) else (
            "✓ " if report.stable == (r["lmgc90"] == "stands") else "✗ ")
        lines.append(f"| {e['name']} | {e['mu']:g} | {e['closed_form'] or '-'} | {r['lmgc90']} |"
                     f" {r['max_disp']:.1e}, {r['max_rot_deg']:.2g} |"
                     f" {', '.join(r.get('moved') or []) or '-'} | {decides} |"
                     f" {mark}{report.status.name} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--lmgc90", action="store_true",
                        help="also run LMGC90 on them (its venv: make lmgc90)")
    parser.add_argument("--table", type=Path, metavar="FOLDER",
                        help="print the markdown table of FOLDER (this one or the suite's)"
                             " instead")
    args = parser.parse_args(argv)
    if args.table:
        print("\n".join(table(args.table)))
        return 0
    from rbe_ros.io.compas import compas_samples_dir
    entries = write(args.out, compas_samples_dir())
    print(f"[squeeze] {len(entries)} variants written to {args.out}")
    if args.lmgc90:
        verdicts = run_lmgc90(args.out)
        (args.out / "lmgc90_verdicts.json").write_text(json.dumps(verdicts, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
