"""The friction threshold is the cone of the check, not a post-check of one solution; and
friction+ never flags an interface at or below it (issue 24, items 2)."""
from __future__ import annotations

import math

import pytest

from helpers import checked, inclined_block
from rbe_ros import generators
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_sequence
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions


def test_wall_within_threshold_at_every_step():
    """A 10 x 8 running-bond wall on design poses needs little friction: with mu 0.6 and a
    threshold of 0.5 every step stands (the post-check of the QP's one solution flagged 61
    of its 84 steps, where course joints sat at mu)."""
    wall = generators.running_bond_wall(courses=8, bricks_per_course=10)
    options = CheckOptions(SolveOptions(mu=0.6), mu_threshold=0.5)
    reports = check_sequence(wall, options)
    assert len(reports) == 84
    assert [r.status for r in reports] == [Status.STABLE] * 84
    assert max(r.worst_friction_ratio for r in reports) <= 0.5 * (1 + 1e-6)


@pytest.mark.parametrize("angle", [27.5, 29.0])
def test_incline_between_threshold_and_mu(angle):
    """A box on an incline needs |V|/N = tan(angle) (closed form), here between the threshold
    0.5 and mu 0.6: it stands with mu alone, exceeds the threshold with it."""
    need = math.tan(math.radians(angle))
    assert 0.5 < need < 0.6
    free = checked(inclined_block(angle), CheckOptions(SolveOptions(mu=0.6)))
    assert free.status == Status.STABLE
    assert free.worst_friction_ratio == pytest.approx(need, rel=1e-4)
    limited = checked(inclined_block(angle), CheckOptions(SolveOptions(mu=0.6), mu_threshold=0.5))
    assert limited.status == Status.FRICTION_EXCEEDED
    assert limited.unstable_blocks == ("box",)
    assert limited.worst_friction_ratio == pytest.approx(need, rel=1e-4)
    assert "threshold" in limited.message


def test_incline_below_threshold_is_stable():
    """tan(20 deg) = 0.364 is within a 0.5 threshold: stable, the ratio the closed form's."""
    report = checked(inclined_block(20.0), CheckOptions(SolveOptions(mu=0.6), mu_threshold=0.5))
    assert report.status == Status.STABLE
    assert report.worst_friction_ratio == pytest.approx(math.tan(math.radians(20.0)), rel=1e-4)


def test_friction_plus_never_flags_at_or_below_threshold():
    """Under friction+ the 14 x 10 dome stands: no interface is flagged as sliding when its
    |V|/N is within the threshold (it was flagged at "|V|/N = 0", an interface whose net force
    was a rounding-level tension), and the same holds with a threshold of 0.3."""
    dome = generators.dome()
    for threshold in (None, 0.3):
        options = CheckOptions(SolveOptions(mu=0.6, friction="plus"), mu_threshold=threshold)
        report = checked(dome, options)
        limit = options.threshold
        flagged = [r for r in report.interfaces if r.friction_exceeded]
        assert all(r.friction_ratio > limit for r in flagged)
        assert report.status == Status.STABLE, report.message
        assert report.worst_friction_ratio <= limit * (1 + 1e-6)
