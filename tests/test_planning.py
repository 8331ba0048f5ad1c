"""Sequence planning: every step of a returned order is re-checked with the plain checker
(the step's held blocks as supports); infeasible plans name the step."""
from __future__ import annotations

import json

import pytest

from oracles import plane_blocks
from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions, HoldSearch
from rbe_ros.analysis.verdict import check
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.pipeline import check_sequence
from rbe_ros.analysis.steps import sequence_steps
from rbe_ros.cli import main
from rbe_ros.scene import make_scene
from rbe_ros.io.scene_json import scene_to_dict


def recheck(plan, original, max_held):
    """Every step of ``plan.scene`` stands by the plain checker, a robot's grip on each held
    block (as ``check --sequence`` checks it); returns the steps."""
    assert plan.feasible, plan.message
    free = sorted(b.id for b in original.blocks if not b.support)
    assert sorted(plan.order) == free and list(plan.scene.sequence) == plan.order
    full = Assembly.from_scene(plan.scene)
    steps = sequence_steps(plan.scene)
    assert [s.held for s in steps] == list(plan.held)
    for step in steps:
        assert len(step.held) <= max_held
        report = check(full.subset(step.present, step.held, step.grips))
        assert report.stable, (step.index, step.block, step.held, report.message)
    last = steps[-1]
    assert last.held == () and set(last.present) == {b.id for b in original.blocks}
    assert all(r.stable for r in plan.reports) and len(plan.reports) == len(steps)
    return steps


def test_wall_is_planned_course_by_course_without_holds():
    wall = generators.running_bond_wall(3, 4)
    plan = plan_sequence(wall, 0)
    steps = recheck(plan, wall, 0)
    assert plan.max_held == 0 and len(steps) == 13     # 4 + 5 + 4 bricks
    courses = [int(b[6:8]) for b in plan.order]
    assert courses == sorted(courses)                   # bottom up


def test_dome_is_planned_with_the_holds_it_needs():
    dome = generators.dome(8, 5)
    plan = plan_sequence(dome, 2)
    steps = recheck(plan, dome, 2)
    assert plan.max_held == 2
    courses = [int(b[6]) for b in plan.order]
    assert courses == sorted(courses)                   # course by course
    # holds are needed: the same order with nothing held fails (at the first block of a ring)
    bare = make_scene(dome.name, dome.blocks, dome.gravity, plan.order)
    seen: list = []
    check_sequence(bare, CheckOptions(holds=HoldSearch(enabled=False)),
                   on_step=lambda r, _total: seen.append(r),
                   cancelled=lambda: any(not r.stable for r in seen))
    assert [r.stable for r in seen] == [False] and seen[0].block_placed == "course1_slice00"
    # an open ring of the top course is held at both ends: its first block and the newest
    top = [s for s in steps if s.block.startswith("course4")]
    assert top[0].held == ("course4_slice00",)
    assert all(s.held == ("course4_slice00", s.block) for s in top[1:-1])
    assert top[-1].held == ()                           # the closed ring stands


@pytest.mark.long
def test_the_papers_dome_is_planned_with_at_most_two_holds():
    """The full 14 x 10 dome (126 blocks to place): every step of the plan stands by the plain
    checker, with at most two blocks held at once (about 30 s)."""
    dome = generators.dome()
    plan = plan_sequence(dome, 2)
    steps = recheck(plan, dome, 2)
    assert len(steps) == 126 and plan.max_held == 2
    assert sum(bool(s.held) for s in steps) > 0


def _holds_needed(plan, supports, blocks, joints):
    """Every step of ``plan`` stands with its holds and needs each of them, by the plane
    rigid-block LP built from the arch's dimensions (tests/oracles/plane_blocks.py)."""
    for step in sequence_steps(plan.scene):
        present = set(step.present) | supports
        assert plane_blocks.stands(blocks, joints, present, supports | set(step.held))
        for h in step.held:
            assert not plane_blocks.stands(blocks, joints, present,
                                           supports | set(step.held) - {h})


def test_arch_with_one_hold_and_the_step_where_none_is_enough():
    """The arch of 7 voussoirs is built holding one block at a time (the key-stone's
    neighbour v04 only touches the crown: placed held), and no block can be placed at step 2
    without a hold: each step and hold, and the failing step, against the plane oracle."""
    arch = generators.semicircular_arch(7)
    blocks, joints, supports = plane_blocks.semicircular_arch(7)
    for k in (1, 2):
        plan = plan_sequence(arch, k)
        recheck(plan, arch, k)
        _holds_needed(plan, supports, blocks, joints)
    assert plan_sequence(arch, 1).max_held == 1
    none = plan_sequence(arch, 0)
    assert not none.feasible and none.failed_step == 2 and none.order == ["v00", "v06"]
    placed = {"v00", "v06"} | supports
    assert plane_blocks.stands(blocks, joints, placed, supports)
    for candidate in set(blocks) - placed:
        smallest = plane_blocks.smallest_holds(blocks, joints, placed | {candidate}, supports)
        assert smallest and all(len(h) == 1 for h in smallest)
    assert "at step 2" in none.message and "needs 1 held block (v01)" in none.message
    # the partial plan stands up to the step that fails
    assert len(none.reports) == 2 and all(r.stable for r in none.reports)


def test_a_finished_assembly_that_does_not_stand_has_no_plan():
    stack = generators.stack(5, offsets=[0.3 * k for k in range(5)])
    plan = plan_sequence(stack, 3)
    assert not plan.feasible and plan.failed_step == 5 and plan.order == []
    assert "finished assembly does not stand" in plan.message
    assert "(TENSION_REQUIRED: tension required: " in plan.message      # why, not only that


def test_keep_sequence_fixes_the_prefix():
    arch = generators.semicircular_arch(7)
    fixed = make_scene(arch.name, arch.blocks, arch.gravity, ["v06", "v00"])
    plan = plan_sequence(fixed, 2, keep_sequence=True)
    recheck(plan, arch, 2)
    assert plan.order[:2] == ["v06", "v00"]


def test_cli_plan_json_and_exit_status(tmp_path, capsys):
    scene = tmp_path / "arch.json"
    scene.write_text(json.dumps(scene_to_dict(generators.semicircular_arch(7))))
    out_scene = tmp_path / "planned.json"
    assert main(["plan", str(scene), "--max-held", "2", "--json", "-o", str(out_scene)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["feasible"] and out["failed_step"] == -1 and out["max_held"] == 2
    assert out["order"] == ["v00", "v06", "v01", "v05", "v02", "v04", "v03"]
    assert [s["held_blocks"] for s in out["steps"]] == [[], [], ["v01"], ["v01", "v05"],
                                                 ["v02", "v05"], ["v02", "v04"], []]
    assert all(s["stable"] and s["status"] == "STABLE" for s in out["steps"])
    planned = json.loads(out_scene.read_text())
    assert planned["sequence"] == out["order"] and planned["holds"] == out["holds"]
    assert {"block": "v05", "from_step": 3, "until_step": 5} in planned["holds"]
    assert main(["plan", str(scene), "--max-held", "0"]) == 1
    text = capsys.readouterr().out
    assert "NOT feasible (step 2)" in text and "order: v00, v06" in text


def test_planned_scene_keeps_the_pose_uncertainty_it_was_planned_under(tmp_path, capsys):
    """The scene file's declaration is written back; a command-line one wins over it."""
    arch = generators.semicircular_arch(7)
    scene = tmp_path / "arch.json"
    scene.write_text(json.dumps(scene_to_dict(make_scene(
        arch.name, arch.blocks, arch.gravity, pose_uncertainty=(0.001, 0.2)))))
    out_scene = tmp_path / "planned.json"
    assert main(["plan", str(scene), "--max-held", "2", "-o", str(out_scene)]) == 0
    assert json.loads(out_scene.read_text())["pose_uncertainty"] == [0.001, 0.2]
    assert main(["plan", str(scene), "--max-held", "2", "--pose-uncertainty", "0.002,0.5",
                 "-o", str(out_scene)]) == 0
    assert json.loads(out_scene.read_text())["pose_uncertainty"] == [0.002, 0.5]
    capsys.readouterr()


@pytest.mark.parametrize("bad", [["--max-held", "-1"], ["--max-held", "1", "--beam", "0"]])
def test_cli_plan_bad_options(tmp_path, capsys, bad):
    scene = tmp_path / "arch.json"
    scene.write_text(json.dumps(scene_to_dict(generators.semicircular_arch(5))))
    assert main(["plan", str(scene), *bad]) == 2
    assert "rbe-ros: error:" in capsys.readouterr().err
