"""~/report of an as-built state under a plan: the state with the plan's holds at its step,
the state ExecutionState's ``as_built`` checks (one definition: ``as_built_state``), checked
as ``check --sequence`` checks the plan's step."""
from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np

from rbe_ros import generators as gen
from rbe_ros.analysis.asbuilt import declared
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis import lookahead
from rbe_ros.analysis.lookahead import (StepRunner, as_built_plan, as_built_state, look_ahead,
                                        state_key)
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_sequence, slim
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.steps import final_state, sequence_step
from rbe_ros.analysis.verdict import check
from rbe_ros.io.execution import (EXECUTION, Execution, NodeReport, Settings, planned_note,
                                  repair)
from rbe_ros.io.messages import report_to_dict
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.replay import asbuilt_check
from rbe_ros.rbe.result import Status
from test_repair import SHIFT, YAW, pose, twin_counterweights


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


def _cases():
    """Small plans at measured poses: the 7-voussoir arch with two holds at the steps that
    hold a block (the note of the plan's step in ~/report), and the twin counterweights
    measured 4 mm out (two failing steps ahead, each repaired)."""
    plan = plan_sequence(gen.semicircular_arch(7), max_held=2).scene
    yield from ((plan, _built(plan, k)) for k in (3, 5))
    twin = twin_counterweights()
    measured = pose(SHIFT, YAW)
    yield twin, scene_at_poses(twin, {a: ([measured["position"][0], y,
                                           measured["position"][2]], measured["orientation"])
                                      for a, y in (("a", 0.0), ("a2", 1.0))})


def _no_time(out):
    return [(kind, {**m, "as_built": {**m["as_built"], "solve_time": 0.0}} if kind == EXECUTION
             else m) for kind, m in out]


def test_the_look_ahead_takes_the_nodes_report_of_the_as_built_state(monkeypatch):
    """~/report's check of the as-built state (``asbuilt_check`` of ``Execution.holding``)
    is the look-ahead's check of it, field by field (the second computation): handed to
    ``Execution.advance``, the look-ahead checks it not again, every other state once, and
    the outputs are those of a look-ahead that checks it; with other options (a margin
    asked for by ``min_margin_g``) the state is checked."""
    keys = []
    real = StepRunner._check

    def counted(self, plan, step, checker):
        keys.append(state_key(plan, step))
        return real(self, plan, step, checker)

    for plan, built in _cases():
        execution = Execution()
        execution.set_design(plan)
        held = execution.holding(built)
        node = asbuilt_check(held).reports[0]
        ahead = look_ahead(plan, built, lookahead_steps=0)
        k = ahead.current_step - 1
        note = planned_note(held, node) if held.holds else ""
        assert note.startswith(" | as the plan has it at step") or plan.name == "twin"
        mine = replace(ahead.as_built, step_index=-1, block_placed="",
                       message=ahead.as_built.message + note, solve_time=node.solve_time)
        assert report_to_dict(mine, {}) == report_to_dict(slim(node), {})
        # its interfaces are those of the look-ahead's state, checked whole
        scene = as_built_plan(plan, built)
        step = sequence_step(scene, k)
        state = Assembly.from_scene(scene, declared(CheckOptions(), scene).contact).subset(
            step.present, step.held, step.grips)
        alone = check(state, declared(CheckOptions(), scene))
        assert [(i.block_a, i.block_b) for i in node.interfaces] == \
            [(i.block_a, i.block_b) for i in alone.interfaces]
        assert np.allclose([i.normal_resultant for i in node.interfaces],
                           [i.normal_resultant for i in alone.interfaces], atol=1e-9)

        settings = Settings(lookahead_steps=0)
        out = {}
        for given in (True, False):
            monkeypatch.setattr(StepRunner, "_check", counted)
            keys.clear()
            execution = Execution()
            execution.set_design(plan)
            report = asbuilt_check(execution.holding(built)).reports[0]
            out[given] = execution.advance(built, report_to_dict(report, {}) if given
                                           else None, {}, CheckOptions(), settings)
            monkeypatch.undo()
            assert len(keys) == len(set(keys))          # no state checked twice
            assert (state_key(scene, step) in keys) is not given
        assert _no_time(out[True]) == _no_time(out[False])
    # other options than the node's: the look-ahead checks the state itself
    execution = Execution()
    execution.set_design(plan)
    report = asbuilt_check(execution.holding(built)).reports[0]
    keys.clear()
    monkeypatch.setattr(StepRunner, "_check", counted)
    execution.advance(built, report_to_dict(report, {}), {}, CheckOptions(),
                      Settings(lookahead_steps=1, min_margin_g=0.01))
    assert keys[0] == state_key(scene, step)


def test_the_execution_begins_while_the_node_checks_the_as_built_state(monkeypatch):
    """The node hands ~/report to the execution as it makes it (``NodeReport``, on its
    check thread): the look-ahead solves the first step ahead before the state's verdict
    is made, and the repair of a failing step begins before the state's tolerance question
    is answered. The outputs are those of the execution given the finished report (the
    replay's; each ExecutionState carries the answer), and no state is checked twice."""
    for plan, built in _cases():
        settings = Settings(lookahead_steps=0)
        execution = Execution()
        execution.set_design(plan)
        report = asbuilt_check(execution.holding(built)).reports[0]
        before = execution.advance(built, report_to_dict(report, {}), {}, CheckOptions(),
                                   settings)
        repaired = any(kind != EXECUTION for kind, _ in before)

        execution = Execution()
        execution.set_design(plan)
        held = execution.holding(built)
        made = NodeReport()
        solved_early, repair_began, answered = (threading.Event() for _ in range(3))
        events, keys = [], []
        whole, checked = lookahead.check, StepRunner._check

        def early(assembly, options):
            events.append(("early", made.waiting))
            solved_early.set()
            return whole(assembly, options)

        def counted(self, plan, step, checker):
            keys.append(state_key(plan, step))
            return checked(self, plan, step, checker)

        def repairer(*args):
            events.append(("repair", not answered.is_set()))
            repair_began.set()
            return repair(*args)

        def decided(verdict):
            made.decide(verdict, {})
            if repaired:            # the tolerance question waits for the repair to begin
                assert repair_began.wait(60)

        def node():
            sent = None
            try:
                assert solved_early.wait(60)    # the verdict waits for the early solve
                sent = asbuilt_check(held, on_verdict=decided).reports[0]
                answered.set()
                # ~/report as the node made it before it handed it over
                assert report_to_dict(replace(sent, solve_time=0.0), {}) == \
                    report_to_dict(replace(report, solve_time=0.0), {})
            finally:
                made.send(sent, {})

        monkeypatch.setattr(lookahead, "check", early)
        monkeypatch.setattr(StepRunner, "_check", counted)
        thread = threading.Thread(target=node)
        thread.start()
        after = execution.advance(built, made, {}, CheckOptions(), settings, repairer)
        thread.join()
        monkeypatch.undo()
        assert answered.is_set()
        assert _no_time(after) == _no_time(before)
        assert events[0] == ("early", True)
        assert [e for e in events if e[0] == "repair"][:1] == ([("repair", True)] if repaired
                                                               else [])
        assert len(keys) == len(set(keys))      # no state checked twice
    assert repaired                             # the twin counterweights: two repairs
