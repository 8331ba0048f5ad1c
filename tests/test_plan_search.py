"""The planner's search backs up on a dead end and says how it ended: a plan, "no plan
exists" (the search exhausted, every refusal proven), "not found within the budget" (with
the deepest partial plan); progress counts candidate checks.

The pocket scene: gravity tilted 40 deg toward +x (tan 40 > mu 0.6: a block alone on the
floor slides, a closed form), block X in a pocket of supports open only toward +x (a roof,
a back wall and two side walls, each 1 cm off X), block Y beside it at the pocket's mouth,
leaning on a stop above X's way out. Y is lower along the tilted gravity, so the greedy
places Y first; then X can come from nowhere (every straight path hits a support or Y: a
sampled sweep of the true shapes with trimesh's collision manager, below). X first slides
out unless held. So: K = 1, X held then Y (found by backing up from Y); K = 0, no plan
(two orders, both refused); a budget of one state: not found within it."""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from oracles import plane_blocks
from rbe_ros import generators
from rbe_ros.analysis import planning
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.planning import (BUDGET_EXHAUSTED, DEAD_END, NO_PLAN, PLANNED,
                                       PlanProgress, plan_sequence)
from rbe_ros.analysis.steps import gripped, sequence_steps
from rbe_ros.analysis.verdict import check
from rbe_ros.cli import main
from rbe_ros.io.scene_json import load_scene, scene_to_dict
from rbe_ros.scene import box_block, make_scene

DATA = Path(__file__).resolve().parent / "data"
TILT = math.radians(40.0)
MU = 0.6


def _box(bid, lo, hi, support=False):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return box_block(bid, hi - lo, (lo + hi) / 2, density=2000.0, support=support)


def pocket():
    """X in a pocket open toward +x, Y at its mouth (see the module docstring)."""
    gap = 0.01
    blocks = [
        _box("floor", (-1, -1, -0.5), (4, 2, 0), True),
        _box("back", (-1, -1, 0), (-gap, 2, 1), True),
        _box("side_a", (0, -1, 0), (0.99, -gap, 1), True),
        _box("side_b", (0, 1 + gap, 0), (0.99, 2, 1), True),
        _box("roof", (-1, -1, 1 + gap), (0.99, 2, 1.5), True),
        _box("stop", (2, 0, 1.1), (3, 1, 2), True),      # above X's way out
        _box("X", (0, 0, 0), (1, 1, 1)),
        _box("Y", (1, 0, 0), (2, 1, 2)),
    ]
    g = 9.81 * np.array([math.sin(TILT), 0.0, -math.cos(TILT)])
    return make_scene("pocket", blocks, g)


def _meshes(scene, ids):
    out = {}
    for b in scene.blocks:
        if b.id in ids:
            assert np.allclose(b.orientation, (0, 0, 0, 1))     # boxes: world = local + position
            out[b.id] = trimesh.Trimesh(b.vertices + b.position, _triangles(b.faces))
    return out


def _triangles(faces):
    return [(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)]


def free_directions(scene, block, present, distance=3.0, samples=400):
    """Directions (of a Fibonacci sphere) along which ``block`` moves ``distance`` m from
    its pose without overlapping a present block: a sampled sweep of the true shapes
    (trimesh's collision manager, independent of rbe_ros.geometry.insertion)."""
    meshes = _meshes(scene, {block, *present})
    manager = trimesh.collision.CollisionManager()
    for bid in present:
        # shrunk by 0.1 mm about its centre: touching faces are not a collision
        m = meshes[bid].copy()
        m.apply_transform(trimesh.transformations.scale_matrix(1 - 1e-4, m.centroid))
        manager.add_object(bid, m)
    moving = meshes[block]
    k = np.arange(samples) + 0.5
    phi, theta = np.arccos(1 - 2 * k / samples), math.pi * (1 + 5 ** 0.5) * k
    lattice = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                        if (i, j, k) != (0, 0, 0)], float)    # the axes, edges and corners
    dirs = np.vstack([lattice / np.linalg.norm(lattice, axis=1)[:, None],
                      np.column_stack([np.cos(theta) * np.sin(phi),
                                       np.sin(theta) * np.sin(phi), np.cos(phi)])])
    free = []
    for d in dirs:
        steps = np.linspace(0.01, distance, 60)
        if not any(manager.in_collision_single(moving, trimesh.transformations.
                                               translation_matrix(t * d)) for t in steps):
            free.append(d)
    return free


SUPPORTS = ("floor", "back", "side_a", "side_b", "roof", "stop")


def test_the_pocket_oracles():
    """What the plans below rest on, without the planner: X alone slides (tan 40 > mu),
    X can come in before Y (toward -x, out of the mouth) and from nowhere after it."""
    scene = pocket()
    assert math.tan(TILT) > MU
    full = Assembly.from_scene(scene)
    assert not check(full.subset([*SUPPORTS, "X"])).stable
    assert check(full.subset([*SUPPORTS, "Y"])).stable
    assert check(full.subset([*SUPPORTS, "X", "Y"])).stable
    before = free_directions(scene, "X", SUPPORTS)
    assert any(np.allclose(d, (1, 0, 0)) for d in before)      # out of the mouth
    assert all(d[0] > 0.9 for d in before)
    assert free_directions(scene, "X", (*SUPPORTS, "Y")) == []


def test_greedy_dead_ends_at_step_1_and_the_search_backs_up():
    scene = pocket()
    plan = plan_sequence(scene, 1)
    assert plan.feasible and plan.outcome == PLANNED, plan.message
    assert plan.order == ["X", "Y"] and plan.held == [("X",), (), ()][:len(plan.held)]
    assert plan.held[0] == ("X",) and plan.max_held == 1
    assert plan.backups == 1            # from Y (placed first by the greedy: lower)
    # every step of the planned scene stands as check --sequence checks it
    full = Assembly.from_scene(plan.scene)
    for step in sequence_steps(plan.scene):
        assert check(full.subset(step.present, step.held, step.grips)).stable, step
    # X arrives moving toward -x, through the pocket's mouth
    assert plan.reports[0].insertable and plan.reports[0].insertion_direction[0] < -0.9


def test_no_plan_exists_with_no_hold():
    plan = plan_sequence(pocket(), 0)
    assert not plan.feasible and plan.outcome == NO_PLAN, plan.message
    assert plan.message.startswith("no plan with at most 0 held exists")
    # the deepest partial plan: Y, then X cannot be inserted
    assert plan.order == ["Y"] and plan.failed_step == 1
    assert "X cannot be inserted" in plan.message
    # a beam does not back up: its dead end is no proof
    beam = plan_sequence(pocket(), 0, beam=2)
    assert beam.outcome == DEAD_END and beam.order == ["Y"] and "--beam 1" in beam.message
    # without the insertion check Y, X is a plan (it is the path that has none)
    loose = plan_sequence(pocket(), 0, _no_insertion())
    assert loose.feasible and loose.order == ["Y", "X"]


def _no_insertion():
    options = CheckOptions()
    return replace(options, insertion=replace(options.insertion, enabled=False))


def test_a_budget_too_small_is_not_found_within_it(tmp_path, capsys):
    path = tmp_path / "pocket.json"
    path.write_text(json.dumps(scene_to_dict(pocket())))
    assert main(["plan", str(path), "--max-held", "1", "--search-budget", "1", "--json"]) == 1
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    # the progress line of Y, placed first: the candidate checks and states so far
    line = next(line for line in captured.err.splitlines() if line.startswith("plan: 1/2"))
    assert ", held: none, " in line and " candidate checks, 1 states of 1, " in line
    assert int(line.split(" candidate checks")[0].rsplit(" ", 1)[1]) >= 1
    assert out["outcome"] == BUDGET_EXHAUSTED and not out["feasible"]
    assert out["message"].startswith("no plan found within the budget (1 states checked")
    assert out["order"] == ["Y"] and out["failed_step"] == 1 and out["search_states"] == 1
    # the keys of before stay
    assert {"feasible", "message", "order", "holds", "search_checks", "steps"} <= set(out)
    assert main(["plan", str(path), "--max-held", "1", "--search-budget", "-1"]) == 2
    assert "--search-budget must be >= 0" in capsys.readouterr().err


def test_the_arch_has_no_plan_without_holds_by_every_subset():
    """The 7-voussoir arch with K = 0: the search is exhausted (no plan exists); an
    independent search over the sets of placed voussoirs (each placed touching one placed
    before) by the plane rigid-block LP (tests/oracles/plane_blocks.py) finds no chain of
    standing sets either, and its largest set is the planner's deepest partial plan."""
    arch = generators.semicircular_arch(7)
    blocks, joints, supports = plane_blocks.semicircular_arch(7)
    free = sorted(set(blocks) - supports)

    def reachable(k):
        """Sets of placed voussoirs reachable by steps that stand with at most k held."""
        sets, frontier = {frozenset()}, [frozenset()]
        while frontier:
            placed = frontier.pop()
            for b in free:
                nxt = placed | {b}
                touches = any({j.a, j.b} & (placed | supports) and b in (j.a, j.b)
                              and {j.a, j.b} != {b} for j in joints)
                if b in placed or nxt in sets or not touches:   # placed touching one
                    continue
                present = nxt | supports
                if plane_blocks.stands(blocks, joints, present, supports) or (
                        k and any(len(h) <= k for h in plane_blocks.smallest_holds(
                            blocks, joints, present, supports))):
                    sets.add(nxt)
                    frontier.append(nxt)
        return sets

    assert frozenset(free) not in reachable(0)
    plan = plan_sequence(arch, 0)
    assert plan.outcome == NO_PLAN and not plan.feasible, plan.message
    deepest = max(len(s) for s in reachable(0))
    assert plan.failed_step == len(plan.order) == deepest
    assert plan_sequence(arch, 1).outcome == PLANNED


def test_progress_counts_candidate_checks():
    seen: list[PlanProgress] = []
    plan = plan_sequence(pocket(), 1, progress=seen.append)
    assert plan.feasible
    placing = [p for p in seen if p.placing]
    # Y (the greedy's), then X held, then Y: each placement reported with the checks so far
    assert [p.block for p in placing] == ["Y", "X", "Y"]
    assert [p.placed for p in placing] == [1, 1, 2]
    checks = [p.checks for p in seen]
    assert checks == sorted(checks) and checks[-1] <= plan.checks and checks[0] >= 1
    assert [p.states for p in placing] == sorted(p.states for p in placing)
    assert placing[-1].backups == 1 and placing[-1].deepest == 2
    assert all(p.estimate >= 0 or p.bound == "unknown" for p in seen)


def test_a_stuck_search_ends_within_the_default_budget(monkeypatch):
    """The default budget ends a search stuck at a step (a candidate refused there, nothing
    deeper since) after planning.STALL candidate checks: 0 here, so the 7-voussoir arch
    without holds (no plan: every order searched, above) ends at the check after its first
    refusal, naming the refused candidate; an explicit budget has no such bound."""
    monkeypatch.setattr(planning, "STALL", 0)
    monkeypatch.setattr(planning, "STALL_STEPS", 0)
    arch = generators.semicircular_arch(7)
    stuck = plan_sequence(arch, 0)
    assert stuck.outcome == BUDGET_EXHAUSTED and not stuck.feasible
    assert stuck.message.startswith("no plan found within the budget (the default's: no "
                                    "deeper partial plan in 0 checks, ")
    assert f"no block can be placed at step {stuck.failed_step} with at most 0 held; the " \
        "best candidate" in stuck.message
    assert plan_sequence(arch, 0, search_budget=1000).outcome == NO_PLAN


@pytest.mark.long
def test_the_capped_dome_ends_within_a_minute_naming_the_wrench():
    """The 10 x 8 dome (issue 31's, tests/data/issue31) with robots of 1200 N / 200 N m:
    the plan ends within 60 s by default (the default budget's stall bound: stuck at step
    40, where every candidate is refused), a plan within them or a failure that names the
    block, the robot on it, the wrench it needs (the check of that step with unbounded
    robots) and the capacity."""
    dome = load_scene(DATA / "issue31" / "dome10x8.json")
    options = replace(CheckOptions(), hold_force_max=1200.0, hold_torque_max=200.0)
    plan = plan_sequence(dome, 2, options)
    assert plan.time < 60.0
    if not plan.feasible:
        f = plan.failure
        assert f["block"] and f["force_max"] == 1200.0 and f["torque_max"] == 200.0
        assert f["wrenches"] and all(w["force"] > 0 for w in f["wrenches"])
        assert f["block"] in plan.message and "1200 N" in plan.message
        assert f"the robot on {f['wrenches'][0]['block']} |F| {f['wrenches'][0]['force']:.4g} N" \
            in plan.message
        # the wrench named is the plain check's of the step with unbounded robots, and the
        # step does not stand with the robots bounded
        full = Assembly.from_scene(dome)
        present = [b.id for b in dome.blocks if b.support] + [*plan.order, f["block"]]
        step = gripped(full, present, frozenset(f["held"]))
        unbounded = check(step)
        assert unbounded.stable
        assert {w.block: round(float(np.linalg.norm(w.force)), 6)
                for w in unbounded.hold_wrenches} == {
            w["block"]: round(w["force"], 6) for w in f["wrenches"]}
        assert not check(step, options).stable
