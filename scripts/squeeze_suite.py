"""Write the squeeze suite (issue 29): tests/data/squeeze/*.json and manifest.json.

Scenes where friction could hold blocks only if they were squeezed (pre-loaded), which blocks
set one at a time never are, and their controls, each at friction coefficients on both sides
of its limit. The scenes come from ``rbe_ros.generators.squeeze`` (``rbe-ros generate squeeze
-p kind=... -o FILE`` makes any of them); the manifest gives each its mu, its verdict from a
closed form where one exists (``"stands"``/``"falls"``, else null) and why. LMGC90's verdicts
are added by ``make bench-lmgc90`` (lmgc90_verdicts.json beside them); tests/
test_squeeze_suite.py compares rbe_ros with both. Deterministic: run it again and nothing
changes.

    python scripts/squeeze_suite.py [--out tests/data/squeeze]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rbe_ros.generators import squeeze  # noqa: E402
from rbe_ros.io.scene_json import scene_to_dict  # noqa: E402

NO_PRELOAD = ("no load makes a normal force on the vertical faces, so nothing resists the"
              " bar's slide down (rigid blocks set one by one carry no pre-load): falls for"
              " any mu")


def _stands(ok: bool) -> str:
    return "stands" if ok else "falls"


def _cantilever(overhang: float, top: bool) -> tuple[str, str]:
    """Tipping about the pier's edge (x = 0): beam 1.0 x 0.15 (centroid overhang - 0.5), top
    block 0.3 x 0.3 (centroid overhang - 0.85); mu plays no part (no horizontal load)."""
    moment = 0.15 * (overhang - 0.5) + (0.09 * (overhang - 0.85) if top else 0.0)
    limit = (0.075 + 0.0765) / 0.24 if top else 0.5
    return _stands(moment <= 0), (f"tips about the pier's edge unless the weights' moment about"
                                  f" it holds the beam down: stands iff overhang <= {limit:.4f}")


def _shelf(length: float, top: bool) -> tuple[str, str]:
    """Tipping about the corbel's edge (x = 0.15): board length x 0.08 (centroid length / 2),
    top block 0.15 x 0.4 (centroid 0.075); the wall's vertical face carries nothing without
    pre-load."""
    moment = 0.08 * length * (length / 2 - 0.15) + (0.06 * (0.075 - 0.15) if top else 0.0)
    limit = (0.012 + math.sqrt(0.012 ** 2 + 4 * 0.04 * 0.0045)) / 0.08 if top else 0.3
    return _stands(moment <= 0), (f"tips about the corbel's edge unless the weights' moment"
                                  f" holds the board down (the wall's face carries nothing"
                                  f" without pre-load): stands iff length <= {limit:.4f}")


def _leaning_posts(angle_deg: float):
    """Statics without pre-load: each post (foot 0.2, height 1.0) tips about its inner foot
    edge O, whose line is the post's inner face, so only the bar's normal force N has a moment
    about O: N = W_post arm / s (arm: the post's centroid beyond O, s: distance along the face
    from O to where N acts, at least 0.7 / cos(angle), the contact's lower edge: N at its
    largest). The bar hangs on the two faces: 2 (F cos - N sin) = W_bar, so it needs
    mu >= F / N. LMGC90's limit is lower (the posts' fall wedges the bar in: dynamic jamming)."""
    a = math.radians(angle_deg)
    arm = 0.5 * math.tan(a) - 0.1
    bar = 0.2 * (0.4 - 0.7 * math.tan(a) + 0.4 - 0.9 * math.tan(a))     # trapezoid area
    normal = 0.2 * arm / (0.7 / math.cos(a))                            # per unit rho g depth
    limit = (bar / 2 + normal * math.sin(a)) / math.cos(a) / normal

    def verdict(mu):
        return _stands(mu >= limit), (
            f"free posts leaning {angle_deg:g} deg on the bar: the posts' weight alone presses"
            f" it (no pre-load), which holds it iff mu >= {limit:.3f}; near that limit"
            f" LMGC90 can stand lower (the falling posts wedge the bar in)")
    return verdict, None


def suite() -> list[dict]:
    """The scenes: name, generator parameters, mu, closed-form verdict (or None) and why."""
    out = []

    def add(name, params, mus, closed, why=None):
        for mu in mus:
            verdict, reason = closed(mu) if callable(closed) else (closed, why)
            out.append({"name": f"{name}_mu{mu:.2f}", "kind": params["kind"], "mu": mu,
                        "params": params, "closed_form": verdict, "why": reason})

    add("pillars", {"kind": "pillars"}, (0.3, 0.6, 0.84, 1.2), "falls",
        "a bar between two free pillars: " + NO_PRELOAD)
    add("lintel", {"kind": "lintel"}, (0.1, 0.6), "stands",
        "the bar lies on the pillars: vertical loads on horizontal faces, stands for any mu")
    add("posts", {"kind": "posts"}, (0.6, 1.2), "falls",
        "a bar between two fixed vertical posts: " + NO_PRELOAD)
    add("wedge10", {"kind": "posts", "angle_deg": 10.0}, (0.1, 0.6), "stands",
        "a keystone whose faces narrow downward (10 deg): normal forces W / (2 sin 10 deg)"
        " carry its weight without friction, stands for any mu")
    add("wedge_inverted10", {"kind": "posts", "angle_deg": -10.0}, (0.6, 1.2), "falls",
        "the faces widen downward (10 deg): moving down opens both contacts, falls for any mu")
    add("leaning_posts15", {"kind": "leaning-posts", "angle_deg": 15.0}, (0.6, 1.2, 5.0),
        *_leaning_posts(15.0))
    add("flat_arch", {"kind": "flat-arch"}, (0.6, 0.84, 1.2), "falls",
        "three blocks with vertical joints between fixed abutments: no load makes a normal"
        " force on a vertical joint and the rigid blocks cannot rotate (locked), so they slide"
        " down together: falls for any mu")
    add("wedged_arch30", {"kind": "wedged-arch", "angle_deg": 30.0}, (0.2, 0.6, 1.0), None,
        "joints through one point below the arch (outer 30 deg, inner 10.9 deg from vertical),"
        " narrowing downward: carries its weight as an arch; no closed form for the limit")
    for angle, mus in ((20.0, (0.25, 0.5)), (30.0, (0.2, 0.5, 0.7)), (40.0, (0.6, 1.0))):
        tan = math.tan(math.radians(angle))
        add(f"incline_pressed{angle:.0f}", {"kind": "incline-pressed", "angle_deg": angle}, mus,
            lambda mu, tan=tan, angle=angle: (_stands(mu >= tan), (
                f"a block on a {angle:.0f} deg incline under a fixed bar lying on it: the bar"
                f" gives no normal force without pre-load, so stands iff mu >= tan {angle:.0f}"
                f" deg = {tan:.4f}")), None)
    tan30 = math.tan(math.radians(30.0))
    add("incline30", {"kind": "incline", "angle_deg": 30.0}, (0.5, 0.7),
        lambda mu: (_stands(mu >= tan30), f"a block alone on a 30 deg incline: stands iff"
                    f" mu >= tan 30 deg = {tan30:.4f}"), None)
    for overhang, top, mus in ((0.55, True, (0.2, 0.6)), (0.72, True, (0.6,)),
                               (0.55, False, (0.6,))):
        name = f"cantilever{overhang * 100:.0f}" + ("" if top else "_alone")
        add(name, {"kind": "cantilever", "overhang": overhang, "top_block": top}, mus,
            *_cantilever(overhang, top))
    for length, mus in ((0.45, (0.6,)), (0.6, (0.6, 1.2))):
        add(f"shelf{length * 100:.0f}", {"kind": "shelf", "overhang": length}, mus,
            *_shelf(length, True))
    add("shelf_pressed", {"kind": "shelf-pressed", "overhang": 0.5}, (0.6, 1.2), "falls",
        "a board against a wall under a fixed block, nothing below it: no load makes a normal"
        " force on the wall, and moving down frees it from the block: falls for any mu")
    add("tower", {"kind": "tower", "overhang": 0.0}, (0.1,), "stands",
        "a straight tower of five blocks: vertical loads only, stands for any mu")
    for shift in (0.15, 0.25):
        add(f"tower_leaning{shift * 100:.0f}", {"kind": "tower", "overhang": shift}, (0.6,),
            _stands(2.5 * shift * 0.3 <= 0.15),
            f"each block shifted {shift * 0.3:.3f} m from the one below: the four upper blocks'"
            f" centroid is 2.5 x that beyond the bottom block's centre, which tips beyond"
            f" its half width 0.15 m: stands iff shift <= 0.2 x 0.3")
    return out


def write(out_dir: Path) -> list[dict]:
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = suite()
    for e in entries:
        data = scene_to_dict(squeeze(**e["params"]))
        data["name"] = e["name"]
        (out_dir / f"{e['name']}.json").write_text(json.dumps(data, indent=None) + "\n")
        e["file"] = f"{e['name']}.json"
    manifest = {"source": "scripts/squeeze_suite.py (rbe_ros.generators.squeeze)",
                "closed_form": "stands, falls, or null where no closed form decides",
                "scenes": entries}
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return entries


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "squeeze")
    args = parser.parse_args(argv)
    entries = write(args.out)
    print(f"[squeeze] {len(entries)} scenes written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
