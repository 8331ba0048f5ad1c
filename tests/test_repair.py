"""Building from measurements (issue 30): the look-ahead of a plan at measured poses and the
repair of its rest (``rbe-ros repair``), checked against closed forms of box stacks (the
centre of mass over the supporting edge) and by ``rbe-ros check --sequence`` of the
repaired plan; ``plan --min-margin`` re-checked by ``check --sequence --margin``."""
from __future__ import annotations

import json
import math
import pickle
from dataclasses import replace

import numpy as np
import pytest

from rbe_ros import generators
from rbe_ros.analysis.asbuilt import declared
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.incremental import StepChecker
from rbe_ros.analysis.lookahead import StepRunner, check_plan_design, look_ahead, state_key
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis import repair as repair_module
from rbe_ros.analysis.repair import repair_plan
from rbe_ros.analysis.steps import sequence_step, step_count
from rbe_ros.analysis.verdict import check
from rbe_ros.cli import main
from rbe_ros.io.execution import Execution, Settings, repair
from rbe_ros.io.messages import lookahead_step_to_dict
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.scene_json import load_scene, scene_to_dict
from rbe_ros.scene import SceneError, box_block, make_scene

#: Block a's measured deviation: 4 mm outward along x, 3 deg about z.
SHIFT, YAW = 0.004, 3.0
RHO = 2000.0


def _box(bid, x0, x1, z0, z1, support=False):
    return box_block(bid, (x1 - x0, 0.4, z1 - z0), ((x0 + x1) / 2, 0, (z0 + z1) / 2),
                     density=RHO, support=support)


#: A counterweighted cantilever on a ground slab whose edge is x = 0: a (overhanging the
#: edge), b on a's overhanging end (a + b stand 2.1 mm inside the edge), c on a's back end.
A, B, C = (-0.6, 0.4), (0.0425, 0.4425), (-0.6, -0.2)


def counterweight(sequence=("a", "b", "c")):
    blocks = [_box("ground", -1.5, 0.0, -0.2, 0.0, True), _box("a", *A, 0.0, 0.2),
              _box("b", *B, 0.2, 0.4), _box("c", *C, 0.2, 0.4)]
    return make_scene("counterweight", blocks, sequence=sequence,
                      pose_uncertainty=(0.005, 3.5))


def com_x(*spans, shift=0.0):
    """x of the centre of mass of boxes of equal section given by their x spans (the
    first shifted by ``shift``): the closed form a step tips by (> 0: beyond the edge)."""
    mass = [x1 - x0 for x0, x1 in spans]
    mid = [(x0 + x1) / 2 for x0, x1 in spans]
    mid[0] += shift
    return sum(m * x for m, x in zip(mass, mid)) / sum(mass)


def pose(x=0.0, yaw=0.0, z=0.1, base=-0.1):
    half = math.radians(yaw) / 2
    return {"position": [base + x, 0.0, z], "orientation": [0, 0, math.sin(half), math.cos(half)]}


@pytest.fixture
def files(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(scene_to_dict(counterweight())))
    measured = tmp_path / "measured.json"
    measured.write_text(json.dumps({"poses": {"a": pose(SHIFT, YAW)}}))
    return tmp_path, plan, measured


def stands_whole(plan, start=0) -> list[bool]:
    """Whether each step of ``plan`` from ``start`` on stands, each state checked whole and
    on its own (its contacts detected on its blocks alone, no forces of another state): the
    second computation of a repaired plan, independent of the repair's incremental walk."""
    options = declared(CheckOptions(), plan)
    out = []
    for k in range(start, step_count(plan)):
        step = sequence_step(plan, k)
        state = Assembly.from_scene(plan.subset(step.present), options.contact)
        out.append(check(state.subset(step.present, step.held, step.grips), options).stable)
    return out


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_the_closed_form_says_where_the_deviation_matters():
    # a + b stand as designed, tip with a 4 mm off; a + c and all three stand either way
    assert com_x(A, B) < -0.002 and com_x(A, B, shift=SHIFT) > 0.0005
    assert com_x(A, C, shift=SHIFT) < -0.1 and com_x(A, B, C, shift=SHIFT) < -0.05


def test_a_later_step_fails_at_the_measured_poses(files, capsys, tmp_path):
    _, plan, measured = files
    # independently: the as-built plan (a measured, b and c at design) by check --sequence
    scene = counterweight()
    built = scene_at_poses(scene, {"a": (pose(SHIFT, YAW)["position"],
                                          pose(SHIFT, YAW)["orientation"])})
    asbuilt = tmp_path / "asbuilt.json"
    asbuilt.write_text(json.dumps(scene_to_dict(make_scene(
        scene.name, [built.block("a") if b.id == "a" else b for b in scene.blocks],
        sequence=scene.sequence, pose_uncertainty=scene.pose_uncertainty))))
    code, out, _ = run(capsys, "check", asbuilt, "--sequence", "--json")
    assert [r["stable"] for r in json.loads(out)["reports"]] == [True, False, True]
    assert stands_whole(load_scene(asbuilt)) == [True, False, True]     # the oracle sees it
    # the look-ahead finds it, step by step, with the as-built state first
    ahead = look_ahead(scene, built, lookahead_steps=0)
    assert ahead.current_step == 1 and ahead.total_steps == 3 and ahead.as_built.stable
    assert ahead.first_failing_step == 1 and [s.block for s in ahead.steps] == ["b", "c"]
    assert not ahead.steps[0].stable and ahead.steps[0].status.name == "TENSION_REQUIRED"
    assert "step 1 (b)" in ahead.message
    one = look_ahead(scene, built, lookahead_steps=1)
    assert [s.step for s in one.steps] == [1]


def test_repair_by_order_every_remaining_step_rechecked(files, capsys):
    tmp, plan, measured = files
    out_file = tmp / "repaired.json"
    code, out, _ = run(capsys, "repair", plan, "--poses", measured, "--json", "-o", out_file)
    result = json.loads(out)
    assert code == 0 and result["feasible"] and result["changed"]
    # no robot in this plan (K 0): only the order saves it, c before b
    assert result["repair"] == "swap" and result["changed_step"] == 1
    assert result["order"] == ["a", "c", "b"] and result["holds"] == []
    assert "step 1 (b)" in result["message"]
    code, out, _ = run(capsys, "check", out_file, "--sequence", "--json")
    reports = json.loads(out)["reports"]
    assert [r["block_placed"] for r in reports] == ["a", "c", "b"]
    assert all(r["stable"] for r in reports)
    assert stands_whole(load_scene(out_file)) == [True] * 3
    assert com_x(A, C, shift=SHIFT) < 0          # the closed form of the new step 1


def test_repair_by_a_hold_within_k(files, capsys):
    tmp, plan, measured = files
    out_file = tmp / "held.json"
    code, out, _ = run(capsys, "repair", plan, "--poses", measured, "--max-held", "1",
                       "--json", "-o", out_file)
    result = json.loads(out)
    assert code == 0 and result["feasible"] and result["repair"] == "hold"
    assert result["order"] == ["a", "b", "c"] and result["held"][1] != []
    assert len(result["held"][1]) == 1 and result["held"][2] == []
    code, out, _ = run(capsys, "check", out_file, "--sequence", "--json")
    reports = json.loads(out)["reports"]
    assert all(r["stable"] for r in reports)
    assert stands_whole(load_scene(out_file)) == [True] * 3
    assert reports[1]["held_blocks"] == result["held"][1]
    # the robot carries what tips: a moment about the edge, so a force > 0
    assert max(math.hypot(*w["force"].values()) for w in reports[1]["hold_wrenches"]) > 0.1


@pytest.mark.parametrize("x", [0.0, -SHIFT])
def test_the_plan_stands_unchanged(files, capsys, x):
    tmp, plan, _ = files
    measured = tmp / "inward.json"
    measured.write_text(json.dumps({"poses": {"a": pose(x, 0.0)}}))
    code, out, _ = run(capsys, "repair", plan, "--poses", measured, "--json")
    result = json.loads(out)
    assert code == 0 and result["feasible"] and not result["changed"]
    assert result["repair"] == "none" and result["order"] == ["a", "b", "c"]
    assert com_x(A, B, shift=x) < 0


def test_no_repair_names_the_step_and_block(tmp_path, capsys):
    # the harmonic stack at 0.98 of its limit, its bottom block 12 mm inward: the three
    # above it are beyond its edge once all are placed, so the finished stack cannot stand
    # and no hold, order or plan saves it
    scene = generators.harmonic_stack(n=4, scale=0.98)
    plan = tmp_path / "stack.json"
    plan.write_text(json.dumps(scene_to_dict(scene)))
    bottom = scene.block("h04")
    measured = tmp_path / "m.json"
    measured.write_text(json.dumps({"poses": {"h04": {
        "position": [float(bottom.position[0]) - 0.012, 0.0, float(bottom.position[2])],
        "orientation": [0, 0, 0, 1]}}}))
    # closed form (Paterson & Zwick): right edges e_k, block k's centre at e_k - 1/2
    e = {4: 0.98 / 8}
    for k in (3, 2, 1):
        e[k] = e[k + 1] + 0.98 / (2 * k)
    top3 = sum(e[k] for k in (1, 2, 3)) / 3 - 0.5
    assert top3 < e[4] and top3 > e[4] - 0.012            # stands as designed, not built
    assert (e[3] + e[2]) / 2 - 0.5 < e[4] - 0.012          # the step before still stands
    code, out, _ = run(capsys, "repair", plan, "--poses", measured, "--max-held", "2",
                       "--json")
    result = json.loads(out)
    assert code == 1 and not result["feasible"] and not result["changed"]
    assert result["message"].startswith("step 3 (h01) fails at the measured poses")
    assert "no build order can end stable" in result["message"]


def test_bad_input_one_line_exit_2(files, capsys):
    tmp, plan, _ = files
    cases = {
        "order.json": ({"b": pose(0, 0, 0.3, 0.2425)}, "not a prefix of the plan's order"),
        "unknown.json": ({"a": pose(), "zz": pose()}, "not in the design"),
    }
    for name, (poses, why) in cases.items():
        (tmp / name).write_text(json.dumps({"poses": poses}))
        code, out, err = run(capsys, "repair", plan, "--poses", tmp / name)
        assert code == 2 and out == "" and why in err and len(err.strip().splitlines()) == 1
    unplanned = tmp / "unplanned.json"
    unplanned.write_text(json.dumps(scene_to_dict(counterweight(sequence=()))))
    code, _, err = run(capsys, "repair", unplanned, "--poses", tmp / "order.json")
    assert code == 2 and "is not a plan" in err
    with pytest.raises(SceneError, match="does not match the design"):
        check_plan_design(counterweight(), make_scene("other", [
            _box("ground", -1.5, 0.0, -0.2, 0.0, True), _box("a", -0.6, 0.5, 0.0, 0.2)]))
    check_plan_design(counterweight(), counterweight(sequence=()))


def test_min_margin_is_honoured_at_every_step(tmp_path, capsys):
    arch = tmp_path / "arch.json"
    arch.write_text(json.dumps(scene_to_dict(generators.semicircular_arch(n=7))))
    planned = tmp_path / "planned.json"
    code, out, _ = run(capsys, "plan", arch, "--max-held", "2", "--json")
    default = json.loads(out)
    assert default["weakest_step"]["step"] == -1       # no margin asked for
    code, out, _ = run(capsys, "plan", arch, "--max-held", "2", "--margin", "--json")
    weakest = json.loads(out)["weakest_step"]
    assert 0.1 < weakest["margin_g"] < 0.13 and weakest["block"]
    code, out, _ = run(capsys, "plan", arch, "--max-held", "2", "--min-margin", "0.13",
                       "--json", "-o", planned)
    result = json.loads(out)
    assert code == 0 and result["weakest_step"]["margin_g"] >= 0.13
    code, out, _ = run(capsys, "check", planned, "--sequence", "--margin", "--json")
    reports = json.loads(out)["reports"]
    assert all(r["stable"] and r["margin_g"] >= 0.13 for r in reports)
    code, out, _ = run(capsys, "plan", arch, "--max-held", "2", "--min-margin", "0.3")
    assert code == 1 and "below the minimum 0.3 g" in out


def test_a_window_checks_and_repairs_the_next_steps_only(files, capsys):
    _, plan, measured = files
    code, out, _ = run(capsys, "repair", plan, "--poses", measured, "--lookahead-steps", "1",
                       "--json")
    result = json.loads(out)
    assert code == 0 and result["repair"] == "swap" and result["order"] == ["a", "c", "b"]
    assert [s["step"] for s in result["steps"]] == [1]
    assert "steps 1 to 1 (the look-ahead) pass" in result["message"]


def test_the_repair_checks_no_state_its_look_ahead_checked(monkeypatch):
    """The node's repair follows its look-ahead on the same as-built state: handed the
    states the look-ahead checked (pickled, as to the node's repair process), it checks
    none of them again, and repairs as it does without them; the look-ahead of the
    repaired plan checks none the repair checked."""
    scene = counterweight()
    measured = pose(SHIFT, YAW)
    built = scene_at_poses(scene, {"a": (measured["position"], measured["orientation"])})
    states = []         # (blocks, supports: the held ones too) of each state checked
    real = StepChecker.check

    def counted(self, assembly, *whole):
        states.append((frozenset(b.id for b in assembly.blocks),
                       frozenset(b.id for b in assembly.blocks if b.support)))
        return real(self, assembly, *whole)

    monkeypatch.setattr(StepChecker, "check", counted)
    alone = repair_plan(scene, built, max_held=1)
    assert alone.kind == "hold" and alone.checks == len(states) == 4
    states.clear()
    ahead = look_ahead(scene, built, lookahead_steps=0)
    looked = set(states)
    # the as-built state, step 1 (b tips a and b over the edge), step 2
    assert ahead.first_failing_step == 1 and len(looked) == len(states) == 3
    states.clear()
    after = repair_plan(scene, built, max_held=1,
                        checked=pickle.loads(pickle.dumps(ahead.checked)))
    # one new state: step 1 with a held; step 2 as the look-ahead checked it
    assert after.checks == len(states) == 1 and not set(states) & looked
    assert states[0] == ({"ground", "a", "b"}, {"ground", *after.held[1]})
    assert [(r.kind, r.order, r.held, r.changed_step, r.message, [s.stable for s in r.steps])
            for r in (alone, after)] == [(after.kind, after.order, after.held,
                                          after.changed_step, after.message,
                                          [True, True])] * 2
    # the node's execution hands them over (its repair in a process of its own)
    handed = []

    def repairer(plan, built, options, settings, cell, checked):
        handed.append(checked)
        return repair(plan, built, options, settings, cell, checked)

    execution = Execution()
    execution.set_design(scene)
    first = look_ahead(scene, built, lookahead_steps=0, until_failure=True).checked
    states.clear()
    out = execution.advance(built, None, {}, CheckOptions(), Settings(lookahead_steps=0),
                            repairer)
    assert [kind for kind, _ in out] == ["execution", "plan_update", "execution"]
    assert out[1][1]["order"] == ["a", "c", "b"]
    assert handed[0].reports.keys() == first.reports.keys()
    # the look-ahead's states up to the failing step 1, then the repair's 1 (K 0: the
    # swap): step 1 with c; then the look-ahead of the repaired plan: step 2 with b
    # placed last (its insertion is b's, not c's)
    assert states == [({"ground", "a"}, {"ground"}), ({"ground", "a", "b"}, {"ground"}),
                      ({"ground", "a", "c"}, {"ground"}),
                      ({"ground", "a", "b", "c"}, {"ground"})]
    assert [s["stable"] for s in out[2][1]["lookahead"]] == [True, True]
    other = scene_at_poses(scene, {"a": (pose()["position"], pose()["orientation"])})
    with pytest.raises(ValueError, match="another as-built state"):
        repair_plan(scene, other, checked=ahead.checked)


def twin_counterweights():
    """Two counterweighted cantilevers side by side (y 0 and 1 m), a and a2 placed first:
    with both measured 4 mm out, the plan's steps 2 (b) and 4 (b2) tip them (the closed
    form of each), the others stand."""
    blocks = [box_block("ground", (1.5, 1.4, 0.2), (-0.75, 0.5, -0.1), density=RHO,
                        support=True)]
    for tag, y in (("", 0.0), ("2", 1.0)):
        blocks += [replace(b, id=b.id + tag, position=b.position + [0.0, y, 0.0])
                   for b in counterweight().blocks if not b.support]
    return make_scene("twin", blocks, sequence=("a", "a2", "b", "c", "b2", "c2"),
                      pose_uncertainty=(0.005, 3.5))


def test_execution_sends_the_failing_step_then_its_repair_then_the_window(monkeypatch):
    """Staged outputs: the look-ahead goes out at its first failing step, the repair of
    that step follows, then the look-ahead of the repaired plan goes on (a second failing
    step: repaired the same way); no state is checked twice, and the final plan and
    ExecutionState are those of one repair of the whole window (the second computation)."""
    scene = twin_counterweights()
    measured = pose(SHIFT, YAW)
    built = scene_at_poses(scene, {a: ([measured["position"][0], y, measured["position"][2]],
                                       measured["orientation"]) for a, y in (("a", 0.0),
                                                                             ("a2", 1.0))})
    # the second computation: the look-ahead of the window, one repair of it, the
    # look-ahead of the repaired plan
    ahead = look_ahead(scene, built, lookahead_steps=0)
    assert [s.passes for s in ahead.steps] == [False, True, False, True]
    whole = repair_plan(scene, built, lookahead_steps=0, checked=ahead.checked)
    assert whole.kind == "swap" and whole.order == ["a", "a2", "c", "b", "c2", "b2"]
    repaired = replace(scene, sequence=tuple(whole.order), holds=whole.holds)
    final = look_ahead(repaired, built, lookahead_steps=0, checked=whole.checked)
    assert final.first_failing_step == -1
    keys = []
    real = StepRunner._check

    def counted(self, plan, step, checker):
        keys.append(state_key(plan, step))
        return real(self, plan, step, checker)

    monkeypatch.setattr(StepRunner, "_check", counted)
    sent = []
    execution = Execution()
    execution.set_design(scene)
    out = execution.advance(built, None, {}, CheckOptions(), Settings(lookahead_steps=0),
                            on_output=lambda kind, message: sent.append(kind))
    assert sent == [k for k, _ in out] == ["execution", "plan_update"] * 2 + ["execution"]
    looked = [[(s["step"], s["block"], s["stable"]) for s in m["lookahead"]]
              for k, m in out if k == "execution"]
    assert looked[:2] == [[(2, "b", False)], [(2, "c", True), (3, "b", True), (4, "b2", False)]]
    assert [m["first_failing_step"] for k, m in out if k == "execution"] == [2, 4, -1]
    assert [(m["changed_step"], m["repair"]) for k, m in out if k == "plan_update"] == \
        [(2, "swap"), (4, "swap")]
    assert len(keys) == len(set(keys))              # each state checked once
    assert list(execution.plan.sequence) == whole.order and execution.plan.holds == whole.holds
    last = out[-1][1]
    assert last["lookahead"] == [lookahead_step_to_dict(s) for s in final.steps]
    assert last["as_built"]["message"] == final.as_built.message
    assert stands_whole(execution.plan, 2) == [True] * 4     # the oracle
    # the same state again (a cell's 10 Hz): its last state, the plan updates sent once
    assert execution.advance(built, None, {}, CheckOptions(), Settings(lookahead_steps=0)) \
        == [out[-1]]


def test_an_as_built_state_that_does_not_stand_says_why_as_the_look_ahead(capsys):
    # a 150 mm out: its centre of mass 50 mm beyond the edge (the closed form), it tips
    assert com_x(A, shift=0.15) > 0.04
    scene = counterweight()
    measured = pose(0.15)
    built = scene_at_poses(scene, {"a": (measured["position"], measured["orientation"])})
    ahead = look_ahead(scene, built)
    assert not ahead.as_built.stable
    # the repair asks the tolerance question of the as-built state only now: the same
    # report as the look-ahead's, whose near contacts were asked of at once
    found = repair_plan(scene, built)
    assert not found.feasible and found.message == \
        f"step 0 (a) does not stand as built: {ahead.as_built.message}"


def test_a_reordered_plan_keeps_each_blocks_approach():
    """A repair that swaps steps moves each block's given approach with it (the node's
    plan under execution pairs approaches with steps by index)."""
    down, b_way, c_way = (0.0, 0.0, -1.0), (0.0, 0.6, -0.8), (0.0, -0.6, -0.8)
    scene = replace(counterweight(), approach=tuple(np.array(d) for d in (down, b_way, c_way)))
    measured = pose(SHIFT, YAW)
    built = scene_at_poses(scene, {"a": (measured["position"], measured["orientation"])})
    execution = Execution()
    execution.set_design(scene)
    out = execution.advance(built, None, {}, CheckOptions(), Settings(lookahead_steps=0),
                            repair)
    assert out[1][1]["order"] == ["a", "c", "b"]
    assert execution.plan.sequence == ("a", "c", "b")
    assert np.allclose(execution.plan.approach_of("b"), b_way)
    assert np.allclose(execution.plan.approach_of("c"), c_way)


def test_the_re_plan_path_checks_no_state_the_planner_checked(monkeypatch):
    """With no hold (K 0) and no swap (a window of none) the counterweight's repair re-plans
    (c before b): the planner checks each state of its plan at the measured poses, and the
    repair takes its steps from those checks, none checked again; the plan is the one the
    re-check of every step made (a, c, b), and each remaining state stands when checked
    whole on its own."""
    scene = counterweight()
    measured = pose(SHIFT, YAW)
    built = scene_at_poses(scene, {"a": (measured["position"], measured["orientation"])})
    monkeypatch.setattr(repair_module, "SWAP_WINDOW", 0)
    events = []         # ("runner", state) of each state the repair's runner checks, then
    real, plan = StepChecker.check, repair_module.plan_sequence

    def counted(self, assembly, *whole):
        events.append(("runner", frozenset(b.id for b in assembly.blocks)))
        return real(self, assembly, *whole)

    def planned(*args, **kwargs):
        found = plan(*args, **kwargs)
        events.append(("planned", found.order))
        return found

    monkeypatch.setattr(StepChecker, "check", counted)
    monkeypatch.setattr(repair_module, "plan_sequence", planned)
    found = repair_plan(scene, built, max_held=0)
    assert found.kind == "replan" and found.feasible and found.order == ["a", "c", "b"]
    # the as-built state and step 1 (b tips a and b over the edge), then the planner's
    assert events == [("runner", {"ground", "a"}), ("runner", {"ground", "a", "b"}),
                      ("planned", ["a", "c", "b"])] and found.checks == 2
    assert [(s.step, s.block, s.stable, s.passes) for s in found.steps] == [
        (1, "c", True, True), (2, "b", True, True)]
    assert stands_whole(found.scene, 1) == [True, True]
    assert com_x(A, B, shift=SHIFT) > 0 > com_x(A, B, C, shift=SHIFT)
    # given approaches other than the planner's choice (down): its checks are not those
    # states' (another path), which the repair checks
    events.clear()
    sideways = (0.0, 0.6, -0.8), (0.0, -0.6, -0.8)
    scene = replace(scene, approach=tuple(np.array(d) for d in ((0, 0, -1.0), *sideways)))
    built = scene_at_poses(scene, {"a": (measured["position"], measured["orientation"])})
    again = repair_plan(scene, built, max_held=0)
    assert again.order == found.order and again.checks == 4
    assert events[-2:] == [("runner", {"ground", "a", "c"}), ("runner", {"ground", "a", "b", "c"})]
