"""The 70-block dome of the robot-cell issue (tests/data/issue31/dome10x8.json, 10 slices x
8 courses, radius 3 m) planned for the cells of examples/cells/: three robots give a plan
whose every state between actions ``rbe-ros check --timeline`` re-checks stable, never more
than three robots busy (counted from the actions), every grip on a face free of the other
blocks and every gripper box clear of them (trimesh), every robot within its payload with
its gripper's weight (a placing robot carrying its block whole, a holding robot holding
it still: its weight and what leans on it); two robots cannot close the fifth course (one robot holds while the
other places, and course5_slice00 and _01 both need holding); UR10s name the first block
none can grip. Long: each plan takes one to a few minutes."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.planning import NO_PLAN
from rbe_ros.analysis.steps import gripped
from rbe_ros.analysis.verdict import check, model_of
from rbe_ros.cli import main
from rbe_ros.geometry.block import pose_blocks
from rbe_ros.io.cell_file import parse_cell
from rbe_ros.io.scene_json import load_scene
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import solve

from test_cell import assert_grips_free, assert_joint_solutions, busy_per_state

pytestmark = pytest.mark.long

DOME = Path(__file__).resolve().parent / "data" / "issue31" / "dome10x8.json"
CELLS = Path(__file__).resolve().parents[1] / "examples" / "cells"
G = 9.81


def norm(v) -> float:
    return float(np.linalg.norm([v["x"], v["y"], v["z"]]))


def test_the_dome_for_three_robots(tmp_path, capsys):
    cell_path = CELLS / "dome_3robots.yaml"
    out = tmp_path / "plan.json"
    capsys.readouterr()
    assert main(["plan", str(DOME), "--cell", str(cell_path), "--json", "-o", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    timeline = result["timeline"]
    assert result["feasible"] and len(result["order"]) == 70
    busy = busy_per_state(timeline)
    assert max(busy) == 3 and busy[-1] == 0
    # the states the K = 2 plan never checked: after course5_slice01 is released at step 42
    # (two robots hold, the third places course5_slice02) the state stands
    assert all(a["stable"] for a in timeline)
    # every robot within its payload, its 20 kg gripper's weight included; a placing robot
    # carries its block whole, (m + m_t) g: the heaviest (course 1, 647 kg) 6.54 kN of 8 kN
    cell = yaml.safe_load(cell_path.read_text())
    robots = {r["name"]: r for r in cell["robots"]}
    mass = {b.id: b.mass for b in pose_blocks(load_scene(DOME).blocks)}
    worst = 0.0
    for a in timeline:
        if a["action"] == "release":
            continue
        r = robots[a["robot"]]
        force, torque = norm(a["wrench_tool"]["force"]), norm(a["wrench_tool"]["torque"])
        assert force <= r["payload_force"] and torque <= r["payload_torque"]
        # the tool frame's force is the block's need plus the gripper's weight carried
        need = np.array([a["wrench_world"]["force"][k] for k in "xyz"])
        carried = need + np.array([0.0, 0.0, r["tool"]["mass"] * G])
        assert force == pytest.approx(float(np.linalg.norm(carried)), rel=1e-9, abs=1e-9)
        if a["action"] == "place":
            assert force == pytest.approx((mass[a["block"]] + r["tool"]["mass"]) * G, rel=1e-9)
        worst = max(worst, force / r["payload_force"])
    heaviest = max(mass[a["block"]] for a in timeline)
    assert worst == pytest.approx((heaviest + 20.0) * G / 8000.0, rel=1e-9)
    # every state re-checked from the export alone
    capsys.readouterr()
    assert main(["check", str(out), "--timeline", "--json", "--strict"]) == 0
    check = json.loads(capsys.readouterr().out)
    assert check["stable"] and check["states"] == len(timeline)
    assert [s["busy"] for s in check["timeline"]] == busy
    scene = load_scene(DOME)
    assert assert_grips_free(scene, cell, timeline) == sum(
        a["action"] != "release" for a in timeline)


def test_the_dome_for_two_robots_fails_naming_the_step(capsys):
    """The K = 2 plan (three robots) holds two blocks after steps 41 and 65; two robots must
    let one go before the next placement, and either hand-over state falls
    (FRICTION_EXCEEDED, a robot's grip on the other). The cell of two (payloads that carry
    every block) fails within the default budget at step 31 needing two held blocks (the
    stall bound: 100 checks at step 31 without a deeper partial plan, counted, so the same
    step on any machine); no payload would do
    (test_two_robots_cannot_build_the_fifth_course_whatever_the_order_or_payload)."""
    scene = load_scene(DOME)
    plan = plan_sequence(scene, 2)
    full = Assembly.from_scene(scene)
    supports = tuple(b.id for b in scene.blocks if b.support)
    for k in (41, 65):
        assert len(plan.held[k]) == 2 and len(plan.held[k + 1]) == 2
        present = supports + tuple(plan.order[:k + 1])
        for keep in plan.held[k]:
            assert check(gripped(full, present, [keep])).status == Status.FRICTION_EXCEEDED
    capsys.readouterr()
    assert main(["plan", str(DOME), "--cell", str(CELLS / "dome_2robots.yaml"),
                 "--json"]) == 1
    result = json.loads(capsys.readouterr().out)
    assert not result["feasible"] and result["failed_step"] == 31
    assert result["outcome"] == "budget_exhausted"
    message = result["message"]
    assert message.startswith("no plan found within the budget (the default's: no deeper "
                              "partial plan in 100 checks, 34 states checked")
    assert "the best candidate, course4_slice01, needs 2 held blocks (course4_slice00, " \
        "course4_slice01)" in message
    assert message.endswith("(a cell of 2 robots: at most 1 hold while one places)")
    # the 31 blocks placed so far: one robot holds course4_slice00 (placed at step 30), none
    # places beside it
    assert max(busy_per_state(result["timeline"])) == 1


def test_the_dome_with_ur10s_names_the_block_none_can_grip(capsys):
    """Every grip of the plan has a UR10 joint solution (checked here by forward
    kinematics); the plan stops at the first block no UR10 reaches and names it, and why
    for each robot."""
    cell_path = CELLS / "dome_ur10.yaml"
    capsys.readouterr()
    assert main(["plan", str(DOME), "--cell", str(cell_path), "--json"]) == 1
    result = json.loads(capsys.readouterr().out)
    message = result["message"]
    block = message.split("no free robot can grip ")[1].split(":")[0]
    assert block not in result["order"]
    assert all(f"{r} cannot grip block {block}" in message for r in ("ur1", "ur2", "ur3"))
    cell = parse_cell(cell_path.read_text(), cell_path.parent)
    assert assert_joint_solutions(cell, result["timeline"]) >= 1


def course(c: int) -> list[str]:
    return [f"course{c}_slice{j:02d}" for j in range(10)]


def test_two_robots_cannot_build_the_fifth_course_whatever_the_order_or_payload():
    """Why no cell of two robots builds the dome, whatever their payload: two robots are one
    hold plus the placing robot, and after the second block of the fifth course is placed one
    of them must let go before anything else is placed. With every course below fixed (a
    relaxation: supports in place of blocks that could move or be missing), two blocks of
    the fifth course with either held have no admissible force field at all (RBE, an
    unbounded robot that may squeeze: infeasible), one alone has none unheld; and the
    planner, with at most one hold and every order of the 30 blocks above the fourth course
    searched, proves that none exists (no_plan, not a budget)."""
    scene = load_scene(DOME)
    below = {b for c in range(1, 5) for b in course(c)}
    top = replace(scene, blocks=tuple(replace(b, support=b.support or b.id in below)
                                      for b in scene.blocks),
                  sequence=tuple(b for b in scene.sequence if b not in below))
    base = tuple(b.id for b in top.blocks if b.support)
    full = Assembly.from_scene(top)
    options = CheckOptions()
    for present, held in ((course(5)[:1], ()), (course(5)[:2], course(5)[:1]),
                          (course(5)[:2], course(5)[1:2]), (course(5)[:9], course(5)[4:5])):
        state = gripped(full, base + tuple(present), held)
        assert not solve(model_of(state, options), options.deciding).solved
        assert not check(state, options).stable
    plan = plan_sequence(top, 1, search_budget=100000)
    assert plan.outcome == NO_PLAN and not plan.feasible
    assert "needs 2 held blocks" in plan.message
