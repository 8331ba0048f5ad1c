"""The plan dispatch of the node, the CLI and replay (:func:`rbe_ros.io.plans.plan_state`) and
the planner's hooks: progress after each placed step, a stop between candidate checks giving
the best partial plan (the uninterrupted plan's prefix, each step re-checked by the plain
checker), limits out of range and capacities this build cannot apply as results, never
exceptions; the action's result dict through the bag's CDR and back."""
from __future__ import annotations

from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.option_spec import BY_PARAM
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.planning import STOPPED, plan_sequence
from rbe_ros.analysis.steps import sequence_steps
from rbe_ros.analysis.verdict import check
from rbe_ros.io import cdr
from rbe_ros.io.bag import to_dict, typestore
from rbe_ros.io.messages import (header_dict, plan_goal_from_dict, plan_goal_to_dict,
                                 plan_result_to_dict, state_to_dict)
from rbe_ros.io.plans import HOLD_CAPACITIES, PlanLimits, plan_options, plan_state
from rbe_ros.io.replay import PLAN_GOAL_TYPE, PLAN_RESULT_TYPE
from rbe_ros.scene import SceneError, ValidationLimits

ARCH = generators.semicircular_arch(7)


def test_progress_and_a_stop_give_the_prefix_of_the_whole_plan():
    whole = plan_sequence(ARCH, 2)
    assert whole.feasible and len(whole.order) == 7
    seen = []
    plan = plan_state(lambda: ARCH, PlanLimits(2), progress=seen.append,
                      should_stop=lambda: len(seen) >= 4)
    assert [p.placed for p in seen] == [1, 2, 3, 4] and {p.total for p in seen} == {7}
    assert [p.block for p in seen] == whole.order[:4]
    assert [p.held for p in seen] == whole.held[:4]
    assert not plan.feasible and plan.failed_step == 4
    assert plan.message.startswith(f"{STOPPED} 4 of 7 blocks")
    assert plan.order == whole.order[:4] and plan.held == whole.held[:4]
    # every planned step stands by the plain checker, with the planned blocks held
    full = Assembly.from_scene(plan.scene)
    steps = sequence_steps(plan.scene)
    assert [s.held for s in steps] == plan.held
    assert all(check(full.subset(s.present, s.held)).stable for s in steps)
    assert [r.held_blocks for r in plan.reports] == [s.held for s in steps]


def test_a_time_limit_stops_the_search():
    plan = plan_state(lambda: generators.dome(), PlanLimits(2, time_limit=1e-9))
    assert plan.message.startswith(f"{STOPPED} 0 of 126 blocks") and plan.order == []


def test_bad_requests_are_plans_that_failed():
    assert plan_state(lambda: ARCH, PlanLimits(-1)).message == \
        "invalid input: max_held must be an integer >= 0, not -1"
    assert plan_state(lambda: ARCH, PlanLimits(2, beam=0)).message.startswith(
        "invalid input: beam must be")

    def unreadable():
        raise SceneError("block 'x': no shape")
    plan = plan_state(unreadable, PlanLimits(2))
    assert (plan.feasible, plan.order, plan.message) == (
        False, [], "invalid input: block 'x': no shape")
    few = CheckOptions(limits=ValidationLimits(max_blocks=8))       # the arch has 9
    assert plan_state(lambda: ARCH, PlanLimits(2), few).message.startswith(
        "invalid input: the scene has 9 blocks, more than the limit of 8")
    for name in HOLD_CAPACITIES:        # the options of that name, where the build has them
        limits = PlanLimits(2, **{name: 100.0})
        if name in BY_PARAM:
            assert BY_PARAM[name].outer(plan_options(CheckOptions(), limits)) == 100.0
        else:
            assert plan_state(lambda: ARCH, limits).message.startswith(
                f"invalid input: {name} 100 asked for")


def through_cdr(msgtype: str, message: dict) -> dict:
    """``message`` encoded as the node records it, decoded as a bag reader reads it."""
    store = typestore()
    return to_dict(store, msgtype, store.deserialize_cdr(cdr.encode(store, msgtype, message),
                                                         msgtype))


def test_goal_and_result_dicts_through_cdr():
    limits = PlanLimits(2, 3, hold_force_max=50.0, time_limit=2.5, search_budget=7,
                        prefer="margin", min_margin=0.05, robust_samples=16)
    goal = through_cdr(PLAN_GOAL_TYPE, plan_goal_to_dict(state_to_dict(ARCH, "cell", 7),
                                                         limits))
    state, back = plan_goal_from_dict(goal)
    assert back == limits and state["header"] == header_dict("cell", 7)
    assert plan_goal_from_dict({**goal, "beam": 0})[1].beam == 1
    plan = plan_sequence(ARCH, 2)
    result = through_cdr(PLAN_RESULT_TYPE, plan_result_to_dict(plan, header_dict("cell", 7)))
    assert result["feasible"] and result["failed_step"] == -1
    assert result["order"] == plan.order and result["plan"]["sequence"] == plan.order
    assert result["holds"] == result["plan"]["holds"] == [
        {"block": h.block, "from_step": h.from_step,
         "until_step": -1 if h.until_step is None else h.until_step,
         # the planner's holds: the check's capacities, the centroid
         "max_force": 0.0, "max_torque": 0.0, "grip": {"x": 0.0, "y": 0.0, "z": 0.0},
         "has_grip": False} for h in plan.scene.holds]
    assert [r["held_blocks"] for r in result["reports"]] == [list(h) for h in plan.held]
