"""Executing a plan for a robot cell (analysis/cell_execution.py, io/execution.py): the
timeline the execution follows is the planner's, a grip moves with its block, a hand-over
state ahead fails as the planner's own hook says it does, and a repair for the cell holds
at a robot's grip with every state of its timeline re-checked by ``rbe-ros check
--timeline`` at the measured poses."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.cell_execution import CellPlan
from rbe_ros.analysis.lookahead import StepRunner, as_built_plan
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.timeline import CellCheck
from rbe_ros.cell import cell_from_dict
from rbe_ros.cli import main
from rbe_ros.io.execution import Execution, Settings
from rbe_ros.io.markers import cell_markers
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.scene import make_block

from helpers import ONE_ROBOT, overhang_stack, stack_stands
from test_cell import ARCH_CELL

HEADER = {"frame_id": "cell", "stamp": {"sec": 1, "nanosec": 0}}
#: Held still, s2 carries its weight and s3's on it (2 x 235 N) and the tool's, at a grip
#: on a side face 0.15 m off its centroid (about 70 N m): 600 N, 150 N m.
ROBOT = {**ONE_ROBOT["robots"][0], "payload_force": 600, "payload_torque": 150}
TWO_ROBOTS = {"robots": [ROBOT, {**ROBOT, "name": "r2", "base": [-0.8, -0.8, 0.0]}]}


def at(scene, blocks, moved=None) -> dict:
    """Poses of ``blocks`` at design, ``moved`` (block -> (offset m, yaw deg)) moved."""
    out = {}
    for b in blocks:
        blk = scene.block(b)
        off, yaw = (moved or {}).get(b, ((0.0, 0.0, 0.0), 0.0))
        q = Rotation.from_euler("z", yaw, degrees=True) * Rotation.from_quat(blk.orientation)
        out[b] = ((blk.position + off).tolist(), q.as_quat().tolist())
    return out


@pytest.fixture(scope="module")
def arch_plan():
    """The 7-voussoir arch planned for three robots (as test_cell's)."""
    plan = plan_sequence(generators.semicircular_arch(7), 2, CheckOptions(),
                         cell=cell_from_dict(ARCH_CELL))
    assert plan.feasible
    return plan


def test_the_timeline_executed_is_the_planners(arch_plan):
    """The timeline derived for the plan (robots, actions, grips) is the one the planner
    made and exported, action by action."""
    cell = CellPlan(arch_plan.timeline.cell, arch_plan.scene, CheckOptions())
    actions, error, failed = cell.actions(arch_plan.scene)
    assert (error, failed) == ("", -1)
    assert [(a.action, a.robot, a.block, a.step, a.before) for a in actions] == [
        (a.action, a.robot, a.block, a.step, a.before) for a in arch_plan.timeline.actions]
    for a, b in zip(actions, arch_plan.timeline.actions):
        assert a.grip.face == b.grip.face and a.grip.point == pytest.approx(b.grip.point)


def test_a_grip_moves_with_its_block(arch_plan):
    """A block measured 4 mm off and turned 3 deg: its grip keeps its place on the block
    (the same point and axes in the block's frame), the grips of blocks at design stay."""
    plan = arch_plan.scene
    built = scene_at_poses(plan, at(plan, ["v00", "v06"],
                                    {"v00": ((0.0, 0.004, 0.0), 3.0)}))
    scene = as_built_plan(plan, built)
    ahead = CellPlan(arch_plan.timeline.cell, plan, CheckOptions()).ahead(
        StepRunner(scene, CheckOptions(), 2))
    place = next(a for a in arch_plan.timeline.actions if a.block == "v00")
    moved = ahead.grip(place.grip)
    before, after = plan.block("v00"), scene.block("v00")
    r0, r1 = (Rotation.from_quat(b.orientation) for b in (before, after))
    assert r1.inv().apply(moved.point - after.position) == pytest.approx(
        r0.inv().apply(place.grip.point - before.position), abs=1e-12)
    assert r1.inv().as_matrix() @ moved.rotation == pytest.approx(
        r0.inv().as_matrix() @ place.grip.rotation, abs=1e-12)
    other = next(a for a in arch_plan.timeline.actions if a.block == "v06")
    assert ahead.grip(other.grip) is other.grip


def test_a_hand_over_state_ahead_fails_as_the_planner_says(arch_plan):
    """The three-robot plan executed by two: to place v02 at step 4, r1 lets go of v01 first
    (v02 absent, v05 held alone). The look-ahead at the as-built state fails there with the
    reason the planner's own hook gives for that step; the steps before pass; no repair
    within two robots saves it, and the reason names the step."""
    plan = arch_plan.scene
    two = cell_from_dict({"robots": ARCH_CELL["robots"][:2]})
    built = scene_at_poses(plan, at(plan, ["v00", "v06"]))
    execution = Execution()
    execution.set_design(plan, two)
    out = execution.advance(built, None, HEADER, CheckOptions(), Settings(lookahead_steps=0))
    assert [k for k, _ in out] == ["execution", "plan_update"]
    (_, ahead), (_, update) = out
    assert ahead["first_failing_step"] == 4 and ahead["current_step"] == 2
    assert [s["stable"] for s in ahead["lookahead"][:2]] == [True, True]
    hook = CellCheck(two, Assembly.from_scene(plan), plan, CheckOptions())
    order = tuple(arch_plan.order)
    why = hook(order[:4], tuple(arch_plan.held[:4]), "v02", arch_plan.held[4])
    assert why.startswith("step 4: the hand-over state after r1 releases v01")
    assert ahead["message"] == \
        f"step 4 (v02) fails at the measured poses: {why[len('step 4: '):]}"
    assert not update["feasible"] and update["timeline"] == []
    assert update["reason"].startswith("step 4 (v02) fails at the measured poses: the "
                                       "hand-over state after r1 releases v01")
    assert "fails for the cell's robots" in update["message"]


def test_a_cell_repair_holds_at_a_robots_grip_and_its_timeline_stands(tmp_path, capsys):
    """The overhang stack planned for two robots, s2 landed 10 mm out and turned 2 deg: s3
    next tips s2 and s3 over s1's edge (the closed form). The repair holds s2 while s3 is
    placed, at the grip the timeline gives its robot, within that robot's payload less its
    tool; every state of the repaired timeline from the deviation on is re-checked
    stable by `rbe-ros check --timeline` of it exported at the measured poses, and the
    markers' index is the last action done."""
    design = overhang_stack()
    cell = cell_from_dict(TWO_ROBOTS)
    plan = plan_sequence(design, 1, CheckOptions(), cell=cell, keep_sequence=True)
    assert plan.feasible and plan.order == ["s1", "s2", "s3", "c"]
    poses = at(plan.scene, ["s1", "s2"], {"s2": ((0.01, 0.0, 0.0), 2.0)})
    assert stack_stands(design, poses, ["s1", "s2"])
    assert not stack_stands(design, poses, ["s1", "s2", "s3"])
    execution = Execution()
    execution.set_design(plan.scene, cell)
    built = scene_at_poses(plan.scene, poses)
    (_, first), (_, update), (_, repaired) = execution.advance(
        built, None, HEADER, CheckOptions(), Settings())
    assert first["first_failing_step"] == 2 and repaired["first_failing_step"] == -1
    assert update["feasible"] and update["repair"] == "hold" and update["changed_step"] == 2
    [hold] = update["holds"]
    assert hold["block"] == "s2" and hold["from_step"] == 2 and hold["until_step"] == 3
    holder = next(a for a in update["timeline"] if a["block"] == "s2" and a["step"] == 2
                  and a["action"] == "hold")
    robot = cell.robot(holder["robot"])
    # the hold's grip is the robot's grip (block frame), its capacity the payload less the
    # tool's weight
    s2 = built.block("s2")
    p = holder["grip"]["pose"]["position"]
    local = Rotation.from_quat(s2.orientation).inv().apply(np.array([p[k] for k in "xyz"])
                                                             - s2.position)
    assert [hold["grip"][k] for k in "xyz"] == pytest.approx(local)
    assert hold["max_force"] == pytest.approx(robot.payload_force - robot.tool.mass * 9.81)
    assert execution.timeline_done == max(i for i, a in enumerate(execution.timeline)
                                          if a["step"] < 2)
    # before the first action: the robots' bases alone
    assert {m["ns"] for m in cell_markers(cell, execution.timeline, -1, HEADER, 1.0)} == {
        "robots", "robot_names"}
    # `rbe-ros check --timeline` of the repaired plan at the measured poses
    doc = scene_to_dict(plan.scene.__class__(
        design.name, tuple(make_block(b.id, b.vertices, b.faces,
                                      *poses.get(b.id, (b.position, b.orientation)),
                                      density=b.density, support=b.support)
                           for b in design.blocks), design.gravity, tuple(update["order"]),
        ()))
    doc["cell"], doc["timeline"] = TWO_ROBOTS, update["timeline"]
    path = tmp_path / "repaired.json"
    path.write_text(json.dumps(doc))
    capsys.readouterr()
    main(["check", str(path), "--timeline", "--json"])
    states = json.loads(capsys.readouterr().out)["timeline"]
    assert len(states) == len(update["timeline"])
    assert all(s["stable"] for s, a in zip(states, update["timeline"]) if a["step"] >= 2)


def test_repair_cli_on_a_cell_plan(tmp_path, capsys):
    """`rbe-ros repair` of a file `plan --cell -o` wrote repairs within its cell: the
    repaired file carries the cell and the timeline, and `check --timeline --strict`
    re-checks every state of it at the measured poses (exit 0). Bad poses (a block out of
    the plan's order, a block not in the design): one line naming them, exit 2."""
    from rbe_ros.io.plan_export import plan_export

    design = overhang_stack()
    plan = plan_sequence(design, 1, CheckOptions(), cell=cell_from_dict(TWO_ROBOTS),
                         keep_sequence=True)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan_export(plan, CheckOptions())))

    def poses(name: str, measured: dict) -> str:
        file = tmp_path / f"{name}.json"
        file.write_text(json.dumps({"poses": {b: {"position": p, "orientation": q}
                                              for b, (p, q) in measured.items()}}))
        return str(file)

    for name, measured, why in [
            ("order", at(design, ["s1", "s3"]), "not a prefix of the plan's order: 's3'"),
            ("ghost", {**at(design, ["s1"]), "ghost": at(design, ["s2"])["s2"]},
             "not in the design 'stack': 'ghost'")]:
        capsys.readouterr()
        assert main(["repair", str(path), "--poses", poses(name, measured)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and why in err
    out = tmp_path / "repaired.json"
    capsys.readouterr()
    assert main(["repair", str(path), "--json", "-o", str(out), "--poses", poses(
        "off", at(design, ["s1", "s2"], {"s2": ((0.01, 0.0, 0.0), 2.0)}))]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["repair"] == "hold" and len(result["timeline"]) == 10
    assert [r["name"] for r in result["cell"]["robots"]] == ["r1", "r2"]
    assert main(["check", str(out), "--timeline", "--strict"]) == 0


def test_a_cell_repair_checks_no_step_state_twice(monkeypatch):
    """The timeline of a cell's repaired plan is checked with the repair's states known: a
    state after an action that is a step state the repair checked (the same blocks, held at
    the same grips) is not checked again, and every state after an action of the remaining
    steps stands."""
    from rbe_ros.analysis import cell_execution, timeline
    from rbe_ros.analysis.incremental import StepChecker

    design = overhang_stack()
    cell = cell_from_dict(TWO_ROBOTS)
    plan = plan_sequence(design, 1, CheckOptions(), cell=cell, keep_sequence=True)
    built = scene_at_poses(plan.scene, at(design, ["s1", "s2"], {"s2": ((0.01, 0.0, 0.0), 2.0)}))
    states = {"repair": [], "timeline": []}
    step_check, state_check = StepChecker.check, timeline.check

    def key(assembly):
        return (frozenset(b.id for b in assembly.blocks),
                frozenset((g.block, g.point if g.point is None else tuple(np.round(g.point, 9)),
                           g.max_force, g.max_torque)
                          for g in assembly.grips))

    def stepped(self, assembly, *whole):
        states["repair"].append(key(assembly))
        return step_check(self, assembly, *whole)

    def checked(assembly, options):
        states["timeline"].append(key(assembly))
        return state_check(assembly, options)

    monkeypatch.setattr(StepChecker, "check", stepped)
    monkeypatch.setattr(timeline, "check", checked)
    found, line = cell_execution.repair_cell(plan.scene, built, CheckOptions(),
                                             CellPlan(cell, plan.scene, CheckOptions()))
    assert found.kind == "hold" and found.order == ["s1", "s2", "s3", "c"]
    assert found.checks == len(states["repair"]) == 4
    assert states["timeline"] and not set(states["timeline"]) & set(states["repair"])
    assert line.feasible and all(a.report.stable for a in line.actions if a.step >= 2)
