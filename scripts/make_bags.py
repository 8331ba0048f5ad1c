#!/usr/bin/env python3
"""Record the regression bags of bags/ (``make bags``): deterministic scenes, fixed stamps,
solve times zeroed, so a rerun on the same code writes byte-identical files.

Each bag holds AssemblyState messages on /rbe_node/assembly, the StabilityReports the
checker made for them on /rbe_node/report and their MarkerArrays on /rbe_node/markers, a
step a second (exactly what ``rbe_node`` would publish; replay
with ``rbe-ros replay BAG --compare`` or ``rbe_ros.io.testing.assert_bag_replays``). The check
options (the defaults) are in metadata.yaml, custom_data ``rbe_ros.check_options``.

* stack_tips: five 1 m boxes, each shifted 0.3 m further along x than the one below. Run 0
  places them one by one: steps 0-2 stand, step 3 (b03) tips the stack about the edge of
  b00 (the blocks above b00 have their centre of mass 0.6 m out, past its edge at 0.5 m);
  the report suggests the one block to hold. Run 1 checks the finished stack as a whole.
* arch_centring: the buttressed arch of Kao et al. 2021 (15 voussoirs) with a centring (one
  support block under each voussoir's intrados, supports with a hold: present until the step
  it is taken away). The buttresses stand from the start; the 15 steps place the voussoirs
  from both springings to the key-stone v07 (step 14). Run 0: the centring released at the
  earliest step from which the arch stands without it, the key-stone's step 14; every step
  stands. Run 1: released one step earlier (13): that step fails. Run 2: no centring: the
  half arches fail from the fourth voussoir on (steps 6-13), each report naming the
  voussoirs a robot must hold; before the key-stone (step 13) the two next to it, v06 and
  v08. Run 3: no centring, the robot holding the minimal set at every step (planned with the
  order fixed, at most 2 held): every step stands.
* dome_courses: the dome of Kao et al. 2021 at 8 slices x 5 courses, built course by course.
  Runs 0-3: the dome up to course 1, 2, 3, 4 as a whole (each complete course stands). Run 4:
  block by block in the order and with the holds ``rbe-ros plan --max-held 2`` finds (the
  first blocks of a course and the two ends of an open ring are held); every step stands.
  The full 14 x 10 dome is planned by benchmarks/plan_dome.py (docs/plan_dome.json).
* wall_misplaced: a running-bond wall of 4 courses of 4 bricks (0.4 m long) in which the
  last brick of the third course (course02_brick03) is placed 0.22 m too far out: it
  overhangs the half brick below it by more than half its length. Run 0 places the bricks
  course by course: from its step (12) on the wall does not stand (the report names it as
  the block to hold) until the half brick placed on it at the end (step 17) pins it down.
  Run 1: the wall as designed, every step stands.

Usage: .venv/bin/python scripts/make_bags.py [--out bags] [--only NAME ...]
"""
from __future__ import annotations

import argparse
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbe_ros import generators  # noqa: E402
from rbe_ros.analysis.options import CheckOptions  # noqa: E402
from rbe_ros.analysis.planning import plan_sequence  # noqa: E402
from rbe_ros.analysis.pipeline import check_sequence  # noqa: E402
from rbe_ros.analysis.steps import sequence_steps  # noqa: E402
from rbe_ros.generators import _prism  # noqa: E402
from rbe_ros.io.replay import STEP_NS, record_bag  # noqa: E402
from rbe_ros.scene import Hold, make_scene  # noqa: E402

#: Stamps of the recorded states: 2024-01-01T00:00:00Z plus one second per run.
STAMP0 = 1_704_067_200 * 1_000_000_000
FRAME = "world"
OPTIONS = CheckOptions()


def stamps(scenes):
    """Each run's state a second after the last report of the run before (reports a second
    apart, :data:`rbe_ros.replay.STEP_NS`), so that Foxglove's timeline shows one step at a
    time and the runs one after the other."""
    out, stamp = [], STAMP0
    for scene in scenes:
        out.append((scene, FRAME, stamp))
        steps = len(sequence_steps(scene)) if scene.sequence else 1
        stamp += (steps + 1) * STEP_NS
    return out


# --- scenes ------------------------------------------------------------------------------------

def stack_scene():
    return generators.stack(5, offsets=[0.0, 0.3, 0.6, 0.9, 1.2])


def with_centring(scene, voussoirs, centre, depth_margin=0.02, rib=0.1, trim=0.1):
    """``scene`` plus one support block "centring_XX" under each voussoir of an arch about
    ``centre`` (its axis along y): a prism whose top face lies in the voussoir's intrados face
    (trimmed by ``trim`` of its length at both ends and ``depth_margin`` m at both sides, so
    it touches nothing else) and ``rib`` m deep."""
    blocks = list(scene.blocks)
    ids = []
    centre = np.asarray(centre, dtype=float)
    for bid in voussoirs:
        b = scene.block(bid)
        world = b.vertices + b.position            # generators pose blocks without rotation
        radial = np.linalg.norm(world[:, [0, 2]] - centre[[0, 2]], axis=1)
        inner = world[np.argsort(radial)[:4]]      # the 4 intrados corners
        mid = inner.mean(axis=0)
        normal = mid - centre
        normal[1] = 0.0
        normal /= np.linalg.norm(normal)           # outward, into the voussoir
        tangent = np.cross([0.0, 1.0, 0.0], normal)
        half_t = 0.5 * (1 - 2 * trim) * np.ptp(inner @ tangent)
        half_y = 0.5 * np.ptp(inner[:, 1]) - depth_margin
        top = [mid + s * half_t * tangent + np.array([0.0, w * half_y, 0.0])
               for s, w in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        bottom = [p - rib * normal for p in top]
        cid = "centring_" + bid.lstrip("v")
        blocks.append(_prism(cid, bottom + top, density=500.0, support=True))
        ids.append(cid)
    return make_scene(scene.name + "+centring", blocks, scene.gravity, scene.sequence), ids


def arch_scenes():
    built = generators.buttressed_arch()          # sequence: buttress courses, then voussoirs
    voussoirs = [b.id for b in built.blocks if b.id.startswith("v")]
    # the buttresses stand from the start; the steps place the voussoirs
    arch = make_scene(built.name, built.blocks, built.gravity,
                      [v for v in built.sequence if v.startswith("v")])
    offset = len(built.sequence) - len(arch.sequence)
    centred, centring = with_centring(arch, voussoirs, (0.0, 0.0, 2.5))  # buttress height
    steps = len(arch.sequence)
    bare = check_sequence(arch, OPTIONS)
    last_unstable = max(r.step_index for r in bare if not r.stable)
    release = last_unstable + 1                    # the earliest step it can be taken away

    def released_at(m):
        return make_scene(centred.name, centred.blocks, centred.gravity, centred.sequence,
                          [Hold(c, 0, m) for c in centring])

    # the holds a robot needs in this order: planned with the whole order fixed (the planner
    # places every free block, so the buttress courses first), shifted to the voussoir steps
    plan = plan_sequence(built, 2, OPTIONS, keep_sequence=True)
    if not plan.feasible:
        raise SystemExit(f"arch: no plan with 2 holds: {plan.message}")
    assert all(h.from_step >= offset for h in plan.scene.holds), plan.scene.holds
    held = make_scene(arch.name, arch.blocks, arch.gravity, arch.sequence,
                      [Hold(h.block, h.from_step - offset, h.until_step - offset)
                       for h in plan.scene.holds])
    info = {"steps": steps, "release_step": release, "keystone": arch.sequence[-1],
            "holds_before_keystone": bare[steps - 2].suggested_holds}
    return [released_at(release), released_at(release - 1), arch, held], info


def dome_scenes():
    dome = generators.dome(8, 5)
    courses = []
    for c in range(1, 5):
        keep = [b.id for b in dome.blocks if int(b.id[6:b.id.index("_")]) <= c]
        courses.append(make_scene(f"dome(8x5) to course {c}",
                                  [b for b in dome.blocks if b.id in keep], dome.gravity))
    plan = plan_sequence(dome, 2, OPTIONS)
    if not plan.feasible:
        raise SystemExit(f"dome: no plan with 2 holds: {plan.message}")
    return courses + [plan.scene], {"max_held": plan.max_held, "plan_time_s": round(plan.time, 1)}


def wall_scenes():
    wall = generators.running_bond_wall(4, 4)
    bad = "course02_brick03"
    blocks = [replace(b, position=b.position + [0.22, 0.0, 0.0]) if b.id == bad else b
              for b in wall.blocks]
    misplaced = make_scene(wall.name + " misplaced", blocks, wall.gravity, wall.sequence)
    return [misplaced, wall], {"misplaced": bad}


BAGS = {"stack_tips": lambda: ([stack_scene(), replace(stack_scene(), sequence=())], {}),
        "arch_centring": arch_scenes,
        "dome_courses": dome_scenes,
        "wall_misplaced": wall_scenes}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "bags"), help="folder of the bags")
    parser.add_argument("--only", nargs="*", choices=sorted(BAGS), help="bags to make")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in args.only or BAGS:
        start = time.perf_counter()
        scenes, info = BAGS[name]()
        path = out / name
        if path.exists():
            shutil.rmtree(path)
        runs = record_bag(path, stamps(scenes), OPTIONS, zero_times=True)
        size = sum(f.stat().st_size for f in path.iterdir())
        print(f"{name}: {len(runs)} runs, {sum(len(r.reports) for r in runs)} reports, "
              f"{size / 1024:.0f} KiB, {time.perf_counter() - start:.1f} s {info}")
        for i, run in enumerate(runs):
            failing = [r["step_index"] for r in run.reports if not r["stable"]]
            print(f"  run {i}: {len(run.reports)} reports, not stable at steps {failing}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
