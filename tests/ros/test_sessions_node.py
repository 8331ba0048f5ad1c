"""RbeNode in-process for a cell's long sessions: a bag split by size whose every file
replays alone (and the directory as a whole), and markers rate-limited to marker_rate_hz
with the newest report's always sent."""
from __future__ import annotations

import time

from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import serialize_message

from rbe_ros import generators
from rbe_ros.io.bag import mcap_files, read_bag
from rbe_ros.io.markers import MARKER_TYPE
from rbe_ros.io.messages import poses_to_dict, scene_from_state_dict, state_to_dict
from rbe_ros.io.replay import REPORT_TYPE, replay_bag
from rbe_ros.ros.convert import dict_to_message

NAMESPACE = "/rbe_sessions_test"


def wait_for_checks(node, count: int, timeout: float = 120.0) -> None:
    """Until the node's worker has published ``count`` reports (no wall-clock bound on a
    check: a generous timeout only against a hang)."""
    end = time.monotonic() + timeout
    while node.health.checks < count:
        assert time.monotonic() < end, f"{node.health.checks} of {count} reports"
        time.sleep(0.02)


def test_split_bag_every_file_replays_alone(make_node, tmp_path):
    from rbe_msgs.msg import AssemblyState, BlockPoses

    wall = generators.running_bond_wall(courses=2, bricks_per_course=2)
    design = state_to_dict(wall, "world", 1_000_000_000)
    poses = {b.id: ([float(v) for v in b.position], [float(v) for v in b.orientation])
             for b in scene_from_state_dict(design).blocks}
    bag = tmp_path / "cell"
    node = make_node(mcap_path=str(bag), max_bag_size_mb=0.008)     # 8 kB a file
    node._on_design(serialize_message(dict_to_message(design, AssemblyState)))
    wait_for_checks(node, 1)
    for k, block in enumerate(wall.sequence):   # one block more in each message, all poses
        placed = {i: poses[i] for i in wall.sequence[:k + 1]}
        message = poses_to_dict(placed, "world", (k + 2) * 1_000_000_000)
        node._on_poses(serialize_message(dict_to_message(message, BlockPoses)))
        wait_for_checks(node, k + 2)
    node.destroy_node()

    files = mcap_files(bag)
    assert len(files) >= 3
    whole = replay_bag(bag, write=False)
    assert whole.matches, whole.diff()
    assert whole.recorded == whole.reports == len(wall.sequence) + 1
    # the last report: the whole wall measured, standing
    last = [r for run in whole.runs for r in run.reports][-1]
    assert last["status"] == 0 and last["stable"]
    assert last["num_blocks"] == len(wall.blocks)
    compared = 0
    for f in files[1:]:
        alone = replay_bag(f, write=False)
        assert alone.matches, f"{f.name}: {alone.diff()}"
        # each later file starts with the settings, the design and the poses so far (one
        # message, stamp 0: no report answers it) once some were measured
        assert alone.runs[0].kind == "design" and alone.runs[0].settings is not None
        carried = [run for run in alone.runs if run.key == (0, 0)]
        assert all(run.kind == "poses" and not run.reports for run in carried)
        compared += alone.recorded
        assert alone.recorded + alone.orphan_reports == len(
            list(read_bag(f, {REPORT_TYPE})))
    assert compared >= 3        # the files alone reproduced reports of as-built walls
    assert len(carried) == 1 and len(carried[0].state["ids"]) >= len(wall.sequence) - 2


def test_marker_rate_limit_sends_the_newest_reports_markers(make_node, rclpy_context, tmp_path):
    from rbe_msgs.msg import AssemblyState
    from rbe_msgs.srv import CheckAssembly

    from rbe_client import stacked_boxes

    rate = 0.5                                      # at most one array every 2 s
    node = make_node(mcap_path=str(tmp_path / "bag"), marker_rate_hz=rate)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    shifts = [0.0, 0.1, 0.2, 0.3, 0.45]             # the last stands (centre 0.05 inside)
    began = time.monotonic()
    for k, shift in enumerate(shifts):
        state = dict_to_message(state_to_dict(stacked_boxes(shift), "", k + 1), AssemblyState)
        node._on_check(CheckAssembly.Request(assembly=state), CheckAssembly.Response())
    elapsed = time.monotonic() - began
    end = time.monotonic() + 30.0                   # the held-back markers come by the timer
    while node._markers_waiting is not None and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    executor.remove_node(node)
    node.destroy_node()
    messages = list(read_bag(tmp_path / "bag", {REPORT_TYPE, MARKER_TYPE}))
    reports = [m for m in messages if m.msgtype == REPORT_TYPE]
    arrays = [m for m in messages if m.msgtype == MARKER_TYPE]
    assert len(reports) == len(shifts)
    # the first report's markers at once, then at most one array per 1/rate s
    assert 2 <= len(arrays) <= 2 + int(elapsed * rate)
    assert len(arrays) < len(reports) or elapsed * rate >= len(shifts) - 2
    stamps = [a.data["markers"][0]["header"]["stamp"]["sec"] for a in arrays]
    assert stamps[0] == 0 and stamps[-1] == 0       # report stamps: the states' (0 s + k ns)
    nanos = [a.data["markers"][0]["header"]["stamp"]["nanosec"] for a in arrays]
    assert nanos[0] == 1 and nanos[-1] == len(shifts)   # the first and the newest report's
    gaps = [b.stamp_ns - a.stamp_ns for a, b in zip(arrays, arrays[1:])]
    assert all(g >= 1e9 / rate * 0.99 for g in gaps)    # never closer than 1/rate
