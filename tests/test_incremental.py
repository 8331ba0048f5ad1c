"""Per-step local models (rbe_ros.analysis.incremental): whatever model answers a step, the
verdict is the full problem's, and a local report's forces are an admissible state of the
whole partial assembly."""
from __future__ import annotations

import collections
from dataclasses import replace

import pytest

from helpers import equilibrium_residual
from rbe_ros import generators as gen
from rbe_ros.analysis.check import CheckOptions, HoldSearch
from rbe_ros.analysis.sequence import check_sequence, sequence_steps
from rbe_ros.scene import make_scene

#: The paper's dome with 7 courses instead of 10 (84 free blocks): built block by block, its
#: partial courses often do not stand, so stable and unstable steps, local and relaxed models
#: all occur.
DOME = gen.dome(slices=14, courses=7)
OPTIONS = CheckOptions(holds=HoldSearch(enabled=False))


def partial_scene(scene, present):
    here = set(present)
    return make_scene(scene.name, [b for b in scene.blocks if b.id in here])


@pytest.fixture(scope="module")
def runs():
    return (check_sequence(DOME, OPTIONS),
            check_sequence(DOME, replace(OPTIONS, full_solve=True)))


def test_local_models_give_the_full_verdict_at_every_step(runs):
    local, full = runs
    assert [r.stable for r in local] == [r.stable for r in full]
    assert {r.model for r in full} == {"full"}
    used = collections.Counter(r.model.split()[0] for r in local)
    assert used["local"] >= 5 and used["relaxed"] >= 5, used     # both shortcuts are exercised
    assert 0 < sum(not r.stable for r in full) < len(full)


def test_a_local_report_is_an_admissible_state_of_the_whole_partial_assembly(runs):
    local, _ = runs
    mu = OPTIONS.solve.mu
    checked = 0
    for step, report in zip(sequence_steps(DOME), local):
        if not report.model.startswith("local"):
            continue
        partial = partial_scene(DOME, step.present)
        present_pairs = {(r.block_a, r.block_b) for r in report.interfaces}
        assert len(present_pairs) == len(report.interfaces)   # every interface once
        assert equilibrium_residual(partial, report) < 1e-6
        for r in report.interfaces:
            assert r.normal_forces.min() > -1e-6 * abs(r.normal_forces).max(initial=1.0)
            assert r.friction_ratio <= mu * (1 + 1e-6)
        checked += 1
    assert checked >= 5


def test_a_relaxed_report_names_why_the_step_fails(runs):
    local, full = runs
    for l_report, f_report in zip(local, full):
        if l_report.model.startswith("relaxed"):
            assert not l_report.stable and not f_report.stable
            assert l_report.unstable_blocks and l_report.message
