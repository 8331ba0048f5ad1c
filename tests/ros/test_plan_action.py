"""The ~/plan action over DDS from an rclpy client: the 7-voussoir arch planned with at most
two holds (feedback after every placed step; the result equal to ``rbe-ros plan --json`` of
the same scene), a dome's plan canceled and one preempted by a newer goal (the best partial
plans), and the node's bag: its goals re-planned by ``rbe-ros replay --compare``, a perturbed
recorded result caught."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest
from action_msgs.msg import GoalStatus
from rbe_msgs.action import PlanSequence

from rbe_ros import generators
from rbe_ros.rbe.result import Status
from rbe_ros.analysis.planning import STOPPED, plan_sequence
from rbe_ros.cli import main
from rbe_ros.io.messages import report_to_dict
from rbe_ros.io.replay import (PLAN, bag_options, compare_plan, compare_report, read_runs,
                               replay_bag, replay_plan, write_runs)
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.ros.convert import message_to_dict
from rbe_ros.ros.live import _Client, live_goal, live_recheck

from helpers import LEDGE_SIGMA, ledge
from rbe_client import node_and_client, stamp_of, state_msg, wait_until

MAX_HELD = 2


@pytest.fixture(scope="module")
def rbe(rclpy_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rbe_plan")
    bag = tmp / "bag"
    with node_and_client(rclpy_context, ["-p", f"mcap_path:={bag}"], tmp / "node.log") \
            as (proc, client):
        yield SimpleNamespace(proc=proc, client=client, bag=bag, tmp=tmp,
                              context=rclpy_context)


def goal_of(scene, max_held: int = MAX_HELD, **limits) -> PlanSequence.Goal:
    return PlanSequence.Goal(assembly=state_msg(scene), max_held=max_held, **limits)


def cli_plan(scene, tmp, capsys) -> dict:
    """``rbe-ros plan --json`` of ``scene``: the plan the action must equal."""
    path = tmp / "scene.json"
    path.write_text(json.dumps(scene_to_dict(scene)))
    capsys.readouterr()
    main(["plan", str(path), "--max-held", str(MAX_HELD), "--json"])
    return json.loads(capsys.readouterr().out)


def test_the_arch_planned_over_dds_equals_rbe_ros_plan(rbe, capsys):
    arch = generators.semicircular_arch(7)
    feedback: list = []
    goal = goal_of(arch)
    handle = rbe.client.send_plan(goal, feedback)
    # feedback after every placed step, placed rising to 7, all taken before the result is
    # asked for: rclpy's action client drops a goal's feedback taken with or after its result
    wait_until(lambda: max((f.placed for f in feedback), default=0) == 7, 120.0,
               "the feedback of 7 steps")
    status, result = rbe.client.result(handle, timeout=120.0)
    expected = cli_plan(arch, rbe.tmp, capsys)
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert expected["feasible"] and result.feasible
    assert list(result.order) == expected["order"] and len(result.order) == 7
    assert result.message == expected["message"]
    assert result.failed_step == expected["failed_step"] == -1
    sent = [message_to_dict(h) for h in result.holds]
    # the planner's holds grip at the centroid, with the check's capacities (the scene
    # file leaves those keys out)
    default = {"max_force": 0.0, "max_torque": 0.0, "has_grip": False,
               "grip": {"x": 0.0, "y": 0.0, "z": 0.0}}
    assert all({k: h[k] for k in default} == default for h in sent)
    holds = [{k: v for k, v in h.items() if k not in default} for h in sent]
    assert holds == expected["holds"] and holds
    assert max(h["until_step"] - h["from_step"] for h in holds) >= 1
    # each step's report: the step, the block placed, the verdict and the blocks held
    rows = [(r.step_index, r.block_placed, Status(r.status).name, r.stable,
             list(r.held_blocks)) for r in result.reports]
    assert rows == [(r["step"], r["block"], r["status"], r["stable"], r["held_blocks"])
                    for r in expected["steps"]]
    assert all(r.stable for r in result.reports)
    # and every force of every step as the core computes it (within replay's tolerances)
    plan = plan_sequence(arch, MAX_HELD)
    header = message_to_dict(result.reports[0].header)
    for report, step in zip(plan.reports, result.reports):
        assert not compare_report(report_to_dict(report, header), message_to_dict(step))
    assert max(len(r.held_blocks) for r in result.reports) <= MAX_HELD
    # the planned assembly: the placed blocks in the planned order with the planned holds,
    # with the goal's stamp on it and on every report
    assert list(result.plan.sequence) == expected["order"]
    assert [message_to_dict(h) for h in result.plan.holds] == sent
    assert {stamp_of(r) for r in [*result.reports, result.plan]} == {stamp_of(goal.assembly)}
    # between steps, heartbeats repeat the step with the candidate checks so far
    checks = [f.checks for f in feedback]
    assert checks == sorted(checks) and checks[-1] > 0
    feedback = [f for k, f in enumerate(feedback) if f.placed and (
        k == 0 or (f.placed, f.step) != (feedback[k - 1].placed, feedback[k - 1].step))]
    assert [f.placed for f in feedback] == list(range(1, 8))
    assert all(f.total == 7 for f in feedback)
    assert [f.block for f in feedback] == expected["order"]
    assert [f.step for f in feedback] == list(range(7))
    steps = {r["step"]: r["held_blocks"] for r in expected["steps"]}
    assert [sorted(f.held) for f in feedback] == [sorted(steps[k]) for k in range(7)]
    assert all(b >= a >= 0 for a, b in zip([f.elapsed for f in feedback],
                                           [f.elapsed for f in feedback][1:]))


def test_a_dome_plan_canceled_then_one_preempted(rbe):
    """Canceled after its first placed steps: CANCELED, the best partial plan (fewer blocks
    than the dome's, each planned step's report); a running plan that a newer goal preempts:
    ABORTED with its partial plan, the newer one planned."""
    dome = generators.dome()        # 126 blocks: a plan of a minute or more
    total = sum(not b.support for b in dome.blocks)
    client = rbe.client
    feedback: list = []
    handle = client.send_plan(goal_of(dome), feedback)
    wait_until(lambda: len(feedback) >= 2, 120.0, "two placed steps of the dome")
    client.cancel(handle)
    status, result = client.result(handle, timeout=120.0)
    assert status == GoalStatus.STATUS_CANCELED
    placed = len(result.order)
    assert 2 <= placed < total
    assert not result.feasible and result.failed_step == placed
    assert result.message.startswith(f"{STOPPED} {placed} of {total} blocks")
    assert [r.block_placed for r in result.reports][:placed] == list(result.order)
    # the feedback taken before the result (a step placed while the cancel was on its way
    # may come with the result, and rclpy drops that): a prefix of the partial plan
    # (heartbeats repeat a step)
    blocks = {f.placed: f.block for f in feedback if f.placed}
    assert sorted(blocks) == list(range(1, len(blocks) + 1)) and len(blocks) >= 2
    assert list(result.order)[:len(blocks)] == [blocks[k] for k in sorted(blocks)]

    feedback = []
    first = client.send_plan(goal_of(dome), feedback)
    wait_until(lambda: feedback, 120.0, "a placed step of the dome")
    arch = generators.semicircular_arch(7)
    second = client.send_plan(goal_of(arch), [])
    status, result = client.result(first, timeout=120.0)
    assert status == GoalStatus.STATUS_ABORTED
    assert result.message.startswith(STOPPED) and not result.feasible
    assert 1 <= len(result.order) < total
    status, result = client.result(second, timeout=120.0)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.feasible
    assert len(result.order) == 7


def test_bad_limits_are_an_infeasible_result(rbe):
    status, result = rbe.client.result(rbe.client.send_plan(
        goal_of(generators.semicircular_arch(5), max_held=-1), []))
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert not result.feasible and result.message.startswith("invalid input: max_held")
    assert not result.order and not result.reports


def test_the_bag_replays_its_plans(rbe, capsys):
    """Every goal so far re-planned offline through the node's dispatch equals its recorded
    result (the canceled and preempted ones up to as many blocks as they had placed);
    a recorded result with two steps swapped, or a step's friction ratio 1% off, is a
    difference (offline, and live through the running node). Runs after the tests above
    (their goals are the bag's)."""
    runs = [r for r in read_runs(rbe.bag) if r.kind == PLAN]
    assert len(runs) == 5 and all(len(r.reports) == 1 for r in runs)
    capsys.readouterr()
    assert main(["replay", str(rbe.bag), "--compare", "-o", str(rbe.tmp / "replayed")]) == 0
    assert "all recorded reports reproduced" in capsys.readouterr().out
    # the view of the bag: each plan's planned assembly with its steps' reports
    assert main(["view", str(rbe.bag), "-o", str(rbe.tmp / "view.html")]) == 0
    steps = sum(len(r.reports[0]["reports"]) for r in runs)
    assert f"{steps} reports of 5 states written" in capsys.readouterr().out

    arch = runs[0]
    swapped = json.loads(json.dumps(arch.reports[0]))
    swapped["order"][1], swapped["order"][2] = swapped["order"][2], swapped["order"][1]
    forces = json.loads(json.dumps(arch.reports[0]))
    forces["reports"][4]["worst_friction_ratio"] *= 1.01    # step 4's: 0.25 (held still,
    # steps 0-3 need no friction)
    perturbed = rbe.tmp / "perturbed"
    write_runs(perturbed, [arch, arch], [[swapped], [forces]], bag_options(rbe.bag))
    assert main(["replay", str(perturbed), "--compare", "-o", str(rbe.tmp / "p_out")]) == 1
    out = capsys.readouterr().out
    assert "run 0 whole assembly plan result: order: recorded" in out
    assert "run 1 step 4" in out and "worst_friction_ratio: recorded" in out

    # live: the arch's goal sent again to the running node (its settings put back after)
    live = replay_bag(perturbed, write=False, recheck=live_recheck("rbe_node", rbe.context, 60.0))
    assert len(live.runs) == 2 and len(live.replayed) == 2
    assert {(d.run, d.field) for d in live.differences} >= {(0, "order"),
                                                            (1, "worst_friction_ratio")}
    assert not compare_plan(arch.reports[0], live.replayed[0][0])
    stopped = runs[1]       # the canceled dome
    with pytest.raises(ValueError, match="the recorded plan was stopped"):
        live_goal(stopped)


def test_a_search_budget_in_the_goal(rbe):
    """The goal's search_budget is the plan's --search-budget: one state of the 7-voussoir
    arch with no hold (whose search needs more) is not found within the budget."""
    arch = generators.semicircular_arch(7)
    handle = rbe.client.send_plan(goal_of(arch, 0, search_budget=1), [])
    status, result = rbe.client.result(handle, timeout=60.0)
    assert status == GoalStatus.STATUS_SUCCEEDED and not result.feasible
    assert result.message.startswith("no plan found within the budget (1 states checked")
    unbounded = rbe.client.send_plan(goal_of(arch, 0), [])
    status, result = rbe.client.result(unbounded, timeout=60.0)
    assert result.message.startswith("no plan with at most 0 held exists")


@pytest.mark.long           # seconds: three goals, a parameter set, three re-plans
def test_robust_samples_in_the_goal(rbe):
    """The goal's robust_samples is the plan's --robust N: refused with prefer holds, and
    without the node's declared pose uncertainty; with pose_uncertainty_m set, the ledge is
    planned by p_stable (the column first, where margin puts the plate first) as ``plan
    --robust`` plans it; each recorded goal re-plans to its recorded result."""
    scene = ledge(None)             # the node's parameters declare the uncertainty
    handle = rbe.client.send_plan(goal_of(scene, 0, robust_samples=16), [])
    _, result = rbe.client.result(handle, timeout=60.0)
    assert result.message.startswith("invalid input: robust 16 ranks candidates by p_stable")
    goal = goal_of(scene, 0, prefer="margin", robust_samples=16)
    _, result = rbe.client.result(rbe.client.send_plan(goal, []), timeout=60.0)
    assert result.message.startswith("invalid input: robust 16: p_stable samples the declared")
    client = _Client(rbe.context, "rbe_node")      # replay's client sets node parameters
    try:
        client.set_parameters({"pose_uncertainty_m": 3 * LEDGE_SIGMA}, 30.0)
        _, result = rbe.client.result(rbe.client.send_plan(goal, []), timeout=60.0)
        client.set_parameters({"pose_uncertainty_m": 0.0}, 30.0)
    finally:
        client.close()
    # as tests/test_robust_plan.py plans it with plan --robust 16
    assert result.feasible and list(result.order) == ["column", "plate"]
    assert result.weakest_margin_g == pytest.approx(0.125, abs=1e-6)      # the column's
    runs = [r for r in read_runs(rbe.bag) if r.kind == PLAN][-3:]
    assert [r.state["robust_samples"] for r in runs] == [16, 16, 16]
    for run in runs:
        replayed = replay_plan(run)[0]
        assert (replayed["message"], replayed["order"]) == (run.reports[0]["message"],
                                                           run.reports[0]["order"])
