"""~/report of an as-built state under a plan: the state with the plan's holds at its step,
the state ExecutionState's ``as_built`` checks (one definition: ``as_built_state``), checked
as ``check --sequence`` checks the plan's step."""
from __future__ import annotations

from rbe_ros import generators as gen
from rbe_ros.analysis.lookahead import as_built_state, look_ahead
from rbe_ros.analysis.pipeline import check_sequence
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.steps import final_state, sequence_step
from rbe_ros.io.execution import Execution
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.replay import asbuilt_check
from rbe_ros.rbe.result import Status


def _built(plan, placed: int):
    """The plan's first ``placed`` blocks measured at their design poses."""
    at = {b.id: b for b in plan.blocks}
    return scene_at_poses(plan, {i: (at[i].position.tolist(), at[i].orientation.tolist())
                                 for i in plan.sequence[:placed]})


def test_the_report_of_a_state_under_a_plan_applies_its_holds():
    plan = plan_sequence(gen.semicircular_arch(7), max_held=2).scene
    steps = check_sequence(plan)                # the plan's own steps (a second computation)
    k = next(i for i, r in enumerate(steps) if r.held_blocks)   # the first step with a hold
    built = _built(plan, k + 1)
    # the measured blocks alone: the half arch needs tension (what alarmed the operator)
    alone = asbuilt_check(built).reports[0]
    assert alone.status == Status.TENSION_REQUIRED and not alone.held_blocks

    execution = Execution()
    execution.set_design(plan)
    held = execution.holding(built)
    assert execution.holding(built) is held     # a state is checked once
    report = asbuilt_check(held).reports[0]
    assert report.stable and report.held_blocks == steps[k].held_blocks
    assert report.message.endswith(f"| as the plan has it at step {k}: held "
                                   f"{', '.join(steps[k].held_blocks)}")
    assert abs(report.worst_friction_ratio - steps[k].worst_friction_ratio) < 1e-6
    # the state of ExecutionState's as_built: the plan's step k, the same verdict
    present, held_ids = final_state(as_built_state(plan, built))
    step = sequence_step(plan, k)
    assert (set(present), held_ids) == (set(step.present), step.held)
    ahead = look_ahead(plan, built, lookahead_steps=1)
    assert (ahead.as_built.status, ahead.as_built.held_blocks) == (report.status,
                                                                    report.held_blocks)


def test_without_a_plan_or_with_poses_off_the_plan_the_measured_blocks_alone():
    plan = plan_sequence(gen.semicircular_arch(7), max_held=2).scene
    built = _built(plan, 3)
    assert Execution().holding(built) is built          # no plan given
    execution = Execution()
    execution.set_design(plan)
    at = {b.id: b for b in plan.blocks}
    late = plan.sequence[4]                             # measured out of the plan's order
    off = scene_at_poses(plan, {late: (at[late].position.tolist(),
                                       at[late].orientation.tolist())})
    assert execution.holding(off) is off
    assert execution.holding(_built(plan, 0)).holds == ()   # nothing placed: the supports
