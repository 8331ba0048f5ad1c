"""A hold is a robot's wrench within its capacity: closed forms of the smallest wrench, the
capacity's verdicts (STABLE just above, HOLD_EXCEEDED just below), unbounded holds with the
verdicts of holds as supports, and the wrench's balance against the reported interface
forces."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from oracles import plane_blocks
from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.steps import sequence_steps
from rbe_ros.analysis.validate import validated_assembly
from rbe_ros.analysis.verdict import check
from rbe_ros.cli import main
from rbe_ros.io.markers import ARROW, step_markers
from rbe_ros.io.messages import header_dict, report_from_dict, report_json, \
    scene_from_state_dict, state_to_dict
from rbe_ros.io.scene_json import scene_from_dict, scene_to_dict
from rbe_ros.io.table import format_table, largest_hold_force
from rbe_ros.io.view import ViewRun, view_data
from rbe_ros.rbe.result import Status
from rbe_ros.scene import Hold, SceneError, box_block, make_scene

G = 9.81
REL = 5e-3          # the closed forms hold within 0.5%

# two_blocks(shift): a 1 x 1 x 0.5 m box of 2000 kg/m^3 (1000 kg) whose centroid lies
# e = shift - 0.5 m beyond the edge x = 0.5 of the support under it; bottom at z = 0.5
SHIFT, MASS = 0.8, 1000.0
E = SHIFT - 0.5
SIZE = 0.5 ** (1 / 3)          # the box's size: the cube root of its volume


def beyond_edge(a: float, **hold) -> tuple:
    """The box beyond the edge, held at a grip a m beyond that edge in the plane of the
    support (block frame: x = 0.5 + a - shift, z = -0.25, the bottom face)."""
    scene = generators.two_blocks(shift=SHIFT)
    grip = (0.5 + a - SHIFT, 0.0, -0.25)
    return replace(scene, holds=(Hold("top", 0, None, grip, **hold),)), grip


def wrench(report):
    (w,) = report.hold_wrenches
    return w


def test_a_held_block_without_contacts_carries_its_weight_and_the_moment_about_the_grip():
    # a box 1 m above the ground, touching nothing: only the robot holds it
    ground = box_block("ground", (3, 3, 0.2), (0, 0, -0.1), support=True, density=2000.0)
    box = box_block("box", (0.4, 0.6, 0.2), (0.3, -0.2, 1.1), density=2000.0)
    mass = 2000.0 * 0.4 * 0.6 * 0.2
    weight = np.array([0.0, 0.0, -mass * G])
    centroid = np.array([0.3, -0.2, 1.1])
    for grip in (None, (0.15, -0.25, 0.1)):
        scene = make_scene("floating", [ground, box], holds=[Hold("box", 0, None, grip)])
        report = check_scene(scene)
        assert report.status == Status.STABLE and report.held_blocks == ("box",)
        w = wrench(report)
        p = centroid + (np.zeros(3) if grip is None else np.array(grip))
        np.testing.assert_allclose(w.grip_point, p, atol=1e-12)
        np.testing.assert_allclose(w.force, -weight, rtol=REL, atol=REL * mass * G)
        np.testing.assert_allclose(w.torque, -np.cross(centroid - p, weight),
                                   atol=REL * mass * G * 0.3)
        assert w.utilisation == 0.0            # unbounded


def test_pin_grip_beyond_the_edge_carries_what_the_turn_about_it_leaves():
    """A pin fixes its grip point and the box may turn about it (rbe/prestress.py): the
    weight's moment about the pin, m g (a - e), turns the box onto the support, and every
    vertex of the overlap (x in [0.3, 0.5], two at each x) descends at a rate proportional
    to its lever from the pin, l = a (at the edge) and a + 0.2. The placement test's least
    |f|^2 with the pin's force a reaction gives N_i = m g (a - e) l_i / sum l^2 (the
    support's reaction to a rigid turn, as on a uniform elastic bed), and the pin the rest,
    straight up: F = m g (1 - (a - e) sum l / sum l^2). (The least wrench, m g e / a with all
    of N at the edge, is what the capacity verdicts turn on: the next test.)"""
    for a in (0.3, 0.4, 0.7):
        scene, _ = beyond_edge(a, max_torque=0.0)
        w = wrench(check_scene(scene))
        levers = np.array([a, a + 0.2])
        expected = MASS * G * (1.0 - (a - E) * levers.sum() / (levers ** 2).sum())
        assert np.linalg.norm(w.force) == pytest.approx(expected, rel=REL)
        assert w.force[2] == pytest.approx(expected, rel=REL)       # straight up
        np.testing.assert_array_equal(w.torque, 0.0)                # a pin: no torque
    assert expected == pytest.approx(0.5077 * MASS * G, rel=1e-4)   # a = 0.7


def test_a_block_held_still_beyond_an_edge_carries_its_weight():
    """A robot that holds its block still (force and torque) is a support for the placement
    test: nothing presses the block onto the support under it, so the robot carries its
    weight, F = m g up, and the weight's moment about the grip, M = (0, x_g m g, 0) with
    x_g = a - e the grip's lever from the centroid (rbe/prestress.py, _held_still). (RBE
    alone, the least wrench: f = m g e a / (a^2 + l^2), the rest resting on the edge.)"""
    for a in (0.4, 1.2):
        scene, _ = beyond_edge(a)
        w = wrench(check_scene(scene))
        assert w.force[2] == pytest.approx(MASS * G, rel=REL)
        assert np.linalg.norm(w.force[:2]) < REL * MASS * G
        assert w.torque[1] == pytest.approx((a - E) * MASS * G, rel=REL)
        assert abs(w.torque[0]) + abs(w.torque[2]) < REL * MASS * G


def test_capacity_just_above_stands_just_below_is_hold_exceeded():
    a = 0.4
    needed = MASS * G * E / a
    above, _ = beyond_edge(a, max_force=needed * 1.003, max_torque=0.0)
    report = check_scene(above)
    assert report.status == Status.STABLE
    # the pin's reaction to the turn (the test above) would be 0.81 m g: the field that
    # stands within the capacity uses all of it
    assert wrench(report).utilisation == pytest.approx(1.0, rel=REL)
    below, _ = beyond_edge(a, max_force=needed * 0.997, max_torque=0.0)
    report = check_scene(below)
    assert report.status == Status.HOLD_EXCEEDED and not report.stable
    assert report.unstable_blocks == ("top",)
    w = wrench(report)
    assert np.linalg.norm(w.force) == pytest.approx(needed, rel=REL)   # the wrench needed
    assert w.utilisation == pytest.approx(1 / 0.997, rel=REL)
    assert f"block top needs |F| {np.linalg.norm(w.force):.4g} N (capacity 7335 N)" \
        in report.message
    # the check's options are the capacity when the hold gives none
    options = CheckOptions(hold_force_max=needed * 0.997, hold_torque_max=0.0)
    scene, _ = beyond_edge(a)
    assert check_scene(scene, options).status == Status.HOLD_EXCEEDED
    assert check_scene(scene, replace(options, hold_force_max=needed * 1.003)).stable
    # a hold's own capacity wins over the option's
    roomy, _ = beyond_edge(a, max_force=2 * needed)
    assert check_scene(roomy, options).stable


def test_torque_capacity_bounds_the_torque():
    """Held still, the robot's torque is the weight's moment about the grip: with half of it
    the step is HOLD_EXCEEDED naming it, with it the step stands."""
    a = 0.4
    scene, _ = beyond_edge(a)
    free = wrench(check_scene(scene))
    torque = np.linalg.norm(free.torque)
    assert torque == pytest.approx((a - E) * MASS * G, rel=REL)
    report = check_scene(scene, CheckOptions(hold_torque_max=0.5 * torque))
    assert report.status == Status.HOLD_EXCEEDED
    assert f"|M| {torque:.4g} N m (capacity {0.5 * torque:.4g} N m)" in report.message
    assert check_scene(scene, CheckOptions(hold_torque_max=1.01 * torque)).stable


def test_a_step_that_fails_otherwise_is_not_hold_exceeded():
    # an unheld block beyond its edge tips whatever the robot holding another can do
    scene = generators.stack(3, offsets=[0.0, 0.0, 0.7])
    scene = replace(scene, holds=(Hold("b00", 0, None),))
    report = check_scene(scene, CheckOptions(hold_force_max=1.0))
    assert report.status in (Status.TENSION_REQUIRED, Status.INFEASIBLE)


def _unbounded_and_supports(scene, options=CheckOptions()):
    """(status with unbounded grips, status with the held blocks as plain supports) of
    each step of ``scene``."""
    full = validated_assembly(scene, options.limits, options.contact)
    out = []
    for step in sequence_steps(scene):
        with_grips = check(full.subset(step.present, step.held, step.grips), options)
        as_supports = check(full.subset(step.present, step.held), options)
        out.append((step.index, with_grips.status, as_supports.status))
    return out


@pytest.mark.parametrize("name", ["leaning", "arch"])
def test_unbounded_holds_give_the_verdicts_of_holds_as_supports(name):
    if name == "leaning":
        scene = generators.stack(5, offsets=[0.3 * k for k in range(5)])
        scene = replace(scene, holds=(Hold("b02", 2, 4), Hold("b03", 3, 4)))
    else:
        scene = generators.semicircular_arch(7)
        ids = list(scene.sequence)
        scene = replace(scene, holds=(Hold(ids[1], 1, 5), Hold(ids[4], 4, 6)))
    steps = _unbounded_and_supports(scene)
    assert any(s != Status.STABLE for _, _, s in steps) or name == "arch"
    for index, grips, supports in steps:
        assert grips == supports, index


def test_the_wrench_balances_the_block_with_its_reported_interface_forces():
    """Independent of the solver's wrench variables: the held block's weight, the forces its
    interfaces apply to it (from the report) and the wrench sum to zero, forces and moments
    about the grip."""
    scene = generators.semicircular_arch(7)
    ids = list(scene.sequence)
    scene = replace(scene, sequence=tuple(ids), holds=(Hold(ids[2], 2, None),))
    reports = check_sequence(scene)
    blocks = {b.id: b for b in validated_assembly(scene).blocks}
    for r in reports:
        for w in r.hold_wrenches:
            b = blocks[w.block]
            weight = b.mass * np.asarray(scene.gravity)
            force = w.force + weight
            moment = w.torque + np.cross(b.centroid - w.grip_point, weight)
            for it in r.interfaces:
                sign = 1.0 if it.block_b == w.block else -1.0 if it.block_a == w.block else 0.0
                f = sign * (it.normal_forces[:, None] * it.normal + it.tangential_forces)
                force += f.sum(axis=0)
                moment += np.cross(it.polygon - w.grip_point, f).sum(axis=0)
            scale = b.mass * G
            assert np.linalg.norm(force) < 1e-5 * scale
            assert np.linalg.norm(moment) < 1e-5 * scale * b.size


def test_grip_and_capacities_in_the_scene_json_and_the_message_dict():
    scene, grip = beyond_edge(0.4, max_force=900.0, max_torque=0.0)
    data = json.loads(json.dumps(scene_to_dict(scene)))
    assert data["holds"] == [{"block": "top", "from_step": 0, "grip": list(grip),
                              "max_force": 900.0, "max_torque": 0.0}]
    assert scene_from_dict(data).holds == scene.holds
    # the message: capacities <= 0 are the check's options (a pin grip's 0 too)
    back = scene_from_state_dict(state_to_dict(scene))
    assert back.holds == (Hold("top", 0, None, grip, 900.0, None),)
    for bad in ({"max_force": -1.0}, {"grip": [1.0, 2.0]}, {"max_torque": "x"}):
        data["holds"] = [{"block": "top", **bad}]
        with pytest.raises(SceneError, match="hold"):
            scene_from_dict(data)


def test_report_dict_round_trip_and_the_status_constant():
    scene, _ = beyond_edge(0.4, max_force=100.0, max_torque=0.0)
    report = check_scene(scene)
    d = report_json(report)
    assert d["status"] == 6 == int(Status.HOLD_EXCEEDED)
    (hw,) = d["hold_wrenches"]
    assert hw["block"] == "top" and hw["utilisation"] > 1
    back = report_from_dict(d)
    assert back.status == Status.HOLD_EXCEEDED
    np.testing.assert_allclose(back.hold_wrenches[0].force, report.hold_wrenches[0].force)
    np.testing.assert_allclose(back.hold_wrenches[0].grip_point, (0.9, 0.0, 0.5))


def test_cli_hold_capacities(tmp_path, capsys):
    scene, _ = beyond_edge(0.4, max_torque=0.0)
    path = tmp_path / "held.json"
    path.write_text(json.dumps(scene_to_dict(scene)))
    needed = MASS * G * E / 0.4
    args = ["check", str(path), "--json", "--strict", "--hold-force-max"]
    assert main([*args, f"{needed * 1.01}"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == 0
    assert main([*args, f"{needed * 0.99}"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == 6 and "hold exceeded" in out["message"]
    assert main(["check", str(path), "--hold-force-max", "-1"]) != 0
    assert "--hold-force-max" in capsys.readouterr().err


# --- the arch and the dome: the plane oracle, plans within a payload ---------------------------

def _force(w) -> float:
    return float(np.linalg.norm(w.force))


def test_the_plane_oracle_with_a_bounded_force_agrees_with_the_arch_hold_wrenches():
    """The arch's plan checked with pin grips at the centroids: the plane rigid-block LP's
    smallest force (tests/oracles/plane_blocks.py, the held block free with an external
    force: any admissible field) is a lower bound of the check's, whose field is one the
    blocks get set in place without pre-load (rbe/prestress.py). Where the other blocks
    stand without the held ones (the plane oracle again), nothing leans on them and a pin at
    the centroid leaves the weight no moment to turn the block onto a neighbour: the robot
    carries m g (at least one step; the smallest force rests the block on its neighbours).
    Where two are held, the LP's smallest largest force is at most the larger of the two."""
    arch = generators.semicircular_arch(7)
    blocks, joints, supports = plane_blocks.semicircular_arch(7)
    plan = plan_sequence(arch, 2)
    reports = check_sequence(plan.scene, CheckOptions(hold_torque_max=0.0))
    compared = 0
    for step, report in zip(sequence_steps(plan.scene), reports):
        present = set(step.present) | supports
        if not step.held:
            continue
        smallest = plane_blocks.smallest_hold_force(blocks, joints, present, supports,
                                                    set(step.held))
        assert report.stable and math.isfinite(smallest), step.index
        forces = [_force(w) for w in report.hold_wrenches]
        assert smallest <= max(forces) * (1 + REL), step.index
        if len(forces) == 1:
            assert smallest <= forces[0] * (1 + REL), step.index
        if plane_blocks.stands(blocks, joints, present - set(step.held), supports):
            weights = [blocks[w.block].weight for w in report.hold_wrenches]
            assert forces == pytest.approx(weights, rel=REL), step.index
            compared += 1
    assert compared >= 1


@pytest.fixture(scope="module")
def arch_plan():
    arch = generators.semicircular_arch(7)
    plan = plan_sequence(arch, 2)
    return arch, plan, max(largest_hold_force(r) for r in plan.reports)


def test_the_arch_planned_below_its_largest_hold_fails_at_a_step_the_oracle_confirms(arch_plan):
    arch, plan, largest = arch_plan
    assert plan.feasible and plan.held[4] == ("v02", "v05")
    blocks, joints, supports = plane_blocks.semicircular_arch(7)
    # no robots can do with less than the oracle's smallest largest force (torques free)
    for k, (held, report) in enumerate(zip(plan.held, plan.reports)):
        if held:
            present = set(plan.order[:k + 1]) | supports
            assert largest_hold_force(report) >= plane_blocks.smallest_hold_force(
                blocks, joints, present, supports, set(held), torque=True)
    # held still, a voussoir's robot carries at least its weight (what leans on it adds):
    # below it no hold does, and the plan fails at its first step that needs one
    weight = _voussoir_weight(arch)
    limit = 0.8 * largest
    assert limit < weight
    first = next(k for k, held in enumerate(plan.held) if held)
    capped = plan_sequence(arch, 2, CheckOptions(hold_force_max=limit))
    assert not capped.feasible and capped.failed_step == first == 2
    assert capped.order == plan.order[:first]
    assert f"needs |F| {weight:.4g} N (capacity {limit:.4g} N)" in capped.message


def _voussoir_weight(arch) -> float:
    return next(b.mass for b in Assembly.from_scene(arch).blocks if b.id == "v01") * G


def test_a_capped_plan_stopped_names_the_wrench_its_deepest_step_needs(arch_plan):
    """A plan stopped (time limit or caller) after candidates of its deepest step were
    refused says why the best was, as a failed plan does: the robot's wrench against the
    capacity (v02's at step 4 of the uncapped plan). Stopped half-way through the polls of
    the whole search (counted in a run not stopped), that step is the capped plan's last."""
    arch, plan, largest = arch_plan
    limit = 0.8 * largest
    needed = _voussoir_weight(arch)
    whole, polls = [], []
    plan_sequence(arch, 2, CheckOptions(hold_force_max=limit),
                  should_stop=lambda: whole.append(1) and False)
    stopped = plan_sequence(arch, 2, CheckOptions(hold_force_max=limit), should_stop=lambda:
                            polls.append(1) or len(polls) >= len(whole) // 2)
    assert not stopped.feasible and stopped.outcome == "stopped"
    assert stopped.message.startswith("stopped after 2 of 7 blocks")
    assert f"block v01 needs |F| {needed:.4g} N (capacity {limit:.4g} N)" in stopped.message
    assert stopped.failure["block"] == "v01"


@pytest.fixture(scope="module")
def dome_plan():
    dome = generators.dome(8, 5)
    return dome, plan_sequence(dome, 2)


def test_the_dome_plan_holds_the_third_rings_first_block_alone_with_its_weight(dome_plan):
    """The 8 x 5 dome's plan holds the first block of the third ring alone as it is placed
    (step 16): held still on the closed second ring, which stands alone, nothing leans on it
    and the robot carries its weight, m g = 17.45 kN (RBE's least wrench, 5.6 kN, lets it
    rest and rub on the ring: friction no load set in place from rest makes)."""
    dome, plan = dome_plan
    assert plan.feasible
    assert plan.held[16] == (plan.order[16],) == ("course3_slice00",)
    block = next(b for b in Assembly.from_scene(dome).blocks if b.id == "course3_slice00")
    assert largest_hold_force(plan.reports[16]) == pytest.approx(block.mass * G, rel=REL)


@pytest.mark.long
def test_the_dome_planned_below_its_largest_hold_fails_at_its_first_held_block(dome_plan):
    """Below the 8 x 5 dome's step-16 hold (its block's weight) no plan exists with 2
    robots: held still, a block's robot carries at least its weight, and the first ring's
    blocks weigh 36 kN, so the plan fails at step 0 naming that weight."""
    dome, plan = dome_plan
    limit = 0.9 * largest_hold_force(plan.reports[16])
    capped = plan_sequence(dome, 2, CheckOptions(hold_force_max=limit))
    assert not capped.feasible and capped.failed_step == 0
    weight = next(b.mass for b in Assembly.from_scene(dome).blocks
                  if b.id == "course1_slice00") * G
    assert weight > limit and f"needs |F| {weight:.4g} N" in capped.message


def test_cli_plan_with_a_hold_force_limit(tmp_path, capsys, arch_plan):
    arch, _, largest = arch_plan
    path = tmp_path / "arch.json"
    path.write_text(json.dumps(scene_to_dict(arch)))
    assert main(["plan", str(path), "--max-held", "2", "--json",
                 "--hold-force-max", f"{0.8 * largest}"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["failed_step"] == 2 and "block v01 needs" in out["message"]
    assert main(["plan", str(path), "--max-held", "2"]) == 0
    assert "max hold N" in capsys.readouterr().out


def test_the_hold_arrow_the_table_column_and_the_view(tmp_path):
    scene, _ = beyond_edge(0.4, max_torque=0.0)
    report = check_scene(scene)
    w = wrench(report)
    arrows = [m for m in step_markers(scene, report, header_dict("world", 0))["markers"]
              if m["ns"] == "holds"]
    (arrow,) = arrows
    assert arrow["type"] == ARROW
    start, end = np.asarray(arrow["points"])
    np.testing.assert_allclose(start, w.grip_point)
    direction = (end - start) / np.linalg.norm(end - start)
    np.testing.assert_allclose(direction, w.force / np.linalg.norm(w.force), atol=1e-9)
    table = format_table([report])
    assert "max hold N" in table.splitlines()[0]
    assert f"{np.linalg.norm(w.force):.1f}" in table.splitlines()[2]
    run = ViewRun("held", state_to_dict(scene), [report_json(report)])
    (step,) = view_data([run], CheckOptions(), "held")["steps"]
    assert step["max_hold"] == pytest.approx(np.linalg.norm(w.force))
    assert any(line["name"] == "holds 0" for line in step["lines"])
