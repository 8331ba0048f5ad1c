"""A recorded bag as a pytest regression test, in one line.

    from rbe_ros.io.testing import assert_bag_replays, parametrize_bags

    def test_my_bag():
        assert_bag_replays("bags/mine")            # offline; through rbe_node:
                                                   # recheck=rbe_ros.ros.live.live_recheck()

    @parametrize_bags("bags")                      # one test per bag directory in bags/
    def test_every_bag(bag):
        assert_bag_replays(bag)

A bag replays when every recorded state, re-checked, gives the recorded reports within the
tolerances of :mod:`rbe_ros.io.replay`; the assertion message is the readable diff.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from .replay import PLAN, STATE, Recheck, ReplayResult, Tolerances, offline_reports, replay_bag


def assert_bag_replays(path, *, recheck: Recheck = offline_reports,
                       tolerances: Tolerances = Tolerances(), options=None) -> ReplayResult:
    """Re-check every state of the bag at ``path`` (see :func:`replay_bag`, nothing is
    written) and fail with the diff unless all recorded reports are reproduced."""
    live = recheck is not offline_reports
    result = replay_bag(path, write=False, recheck=recheck, tolerances=tolerances,
                        options=options)
    if not result.runs:
        raise AssertionError(f"{path}: the bag holds no rbe_msgs/AssemblyState, BlockPoses "
                             "or PlanSequence goal")
    # a design or poses message the node dropped unchecked under overload has no report
    silent = [i for i, run in enumerate(result.runs)
              if not run.reports and run.kind in (STATE, PLAN)]
    if silent:
        raise AssertionError(f"{path}: no recorded report for run(s) {silent}: nothing to "
                             "compare")
    if result.differences:
        raise AssertionError(f"{path}: the replay{' (live)' if live else ''} differs from the "
                             f"recorded reports in {len(result.differences)} field(s):\n"
                             f"{result.diff()}")
    return result


def bag_paths(folder) -> list[Path]:
    """The bag directories (holding a metadata.yaml) directly under ``folder``, sorted."""
    return sorted(p for p in Path(folder).iterdir() if (p / "metadata.yaml").is_file())


def parametrize_bags(folder, argname: str = "bag"):
    """``pytest.mark.parametrize`` over the bags of ``folder`` (ids: directory names)."""
    paths = bag_paths(folder)
    return pytest.mark.parametrize(argname, paths, ids=[p.name for p in paths])


__all__ = ["assert_bag_replays", "bag_paths", "parametrize_bags"]
