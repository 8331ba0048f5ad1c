"""The node's design-then-measured-poses input: ~/design (or design_file), then ~/poses; each
update merged into the as-built state (none lost, even when its check is dropped under
overload), the newest answered; the bag replays offline and live."""
from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
from rbe_msgs.msg import AssemblyState, BlockPoses, PlanUpdate, StabilityReport
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from rbe_client import NodeProcess, wait_until
from rbe_ros import generators as gen
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.io.bag import read_bag
from rbe_ros.io.messages import poses_to_dict, state_to_dict
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.io.testing import assert_bag_replays
from rbe_ros.rbe.result import Status
from rbe_ros.ros.convert import dict_to_message
from rbe_ros.ros.live import live_recheck

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STAMP0 = 50_000


class Pipeline:
    """A fabrication pipeline's side: publishes a design and measured poses, keeps the
    reports and the plan updates (repairs of a design's plan, made after the report)."""

    def __init__(self, context, base: str = "/rbe_node"):
        self.node = Node("rbe_poses_pipeline", context=context)
        self.design = self.node.create_publisher(AssemblyState, f"{base}/design", LATCHED)
        self.poses = self.node.create_publisher(BlockPoses, f"{base}/poses", RELIABLE)
        self.reports: list[StabilityReport] = []
        self.updates: list[PlanUpdate] = []
        self.lock = threading.Lock()
        self.node.create_subscription(StabilityReport, f"{base}/report", self._keep, RELIABLE)
        self.node.create_subscription(PlanUpdate, f"{base}/plan_update", self._keep_update,
                                      RELIABLE)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.base = base

    def _keep(self, msg):
        with self.lock:
            self.reports.append(msg)

    def _keep_update(self, msg):
        with self.lock:
            self.updates.append(msg)

    def update(self, sec: int):
        with self.lock:
            return next((u for u in self.updates if u.header.stamp.sec == sec), None)

    def ready(self):
        return (self.design.get_subscription_count() >= 1
                and self.poses.get_subscription_count() >= 1
                and self.node.count_publishers(f"{self.base}/report") >= 1)

    def report(self, sec: int):
        with self.lock:
            return next((r for r in self.reports if r.header.stamp.sec == sec), None)

    def close(self):
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(5.0)
        self.node.destroy_node()


def _measured(design, bid: str, dy: float):
    """The design pose of ``bid`` moved by ``dy`` across the wall (keeps every face pair
    coplanar: bed joints and head joints both contain the y axis)."""
    b = design.block(bid)
    return (b.position + [0.0, dy, 0.0]).tolist(), b.orientation.tolist()


# The live replay re-checks all 101 states in a node of its own, one at a time (longer than
# the rest of the test): make test replays this bag offline, make test-long live too; the
# design-file test below replays its (small) design and poses bag live in make test.
@pytest.mark.parametrize("live", [False, pytest.param(True, marks=pytest.mark.long)],
                         ids=["offline", "live"])
def test_design_then_100_pose_updates_at_10_hz(rclpy_context, tmp_path, live):
    design = gen.running_bond_wall(8, 12)                # 100 bricks on a footing
    order = list(design.sequence)
    assert len(order) == 100
    rng = np.random.default_rng(16)
    offsets = rng.uniform(-0.002, 0.002, size=len(order))
    # update k measures brick k; every 10th also measures brick k-1 again, 1 mm further out
    updates = []
    for k, bid in enumerate(order):
        poses = {bid: _measured(design, bid, offsets[k])}
        if k % 10 == 9:
            poses[order[k - 1]] = _measured(design, order[k - 1], offsets[k - 1] + 0.001)
        updates.append(poses)
    bag = tmp_path / "bag"
    proc = NodeProcess(["-p", f"mcap_path:={bag}"], tmp_path / "node.log")
    pipeline = Pipeline(rclpy_context)
    try:
        wait_until(lambda: proc.proc.poll() is None and pipeline.ready(), 60.0, "the node")
        pipeline.design.publish(dict_to_message(
            state_to_dict(design, "wall", STAMP0 * 1_000_000_000), AssemblyState))
        first = wait_until(lambda: pipeline.report(STAMP0), 30.0, "the design's report")
        assert first.status == Status.STABLE and first.num_blocks == 1   # the footing alone
        start = time.monotonic()
        for k, poses in enumerate(updates):
            time.sleep(max(0.0, start + k / 10.0 - time.monotonic()))
            pipeline.poses.publish(dict_to_message(
                poses_to_dict(poses, "wall", (STAMP0 + 1 + k) * 1_000_000_000), BlockPoses))
        last = STAMP0 + len(updates)
        wait_until(lambda: pipeline.report(last), 60.0, "the last update's report")
        time.sleep(0.5)
    finally:
        pipeline.close()
        assert proc.stop() == 0
    assert "Traceback" not in proc.output()
    reports = sorted(pipeline.reports, key=lambda r: r.header.stamp.sec)
    stamps = [r.header.stamp.sec for r in reports]
    # newest wins: every report answers a distinct message, the last the last update, and
    # every message is answered or counted as dropped (the node keeps every pose update)
    assert stamps == sorted(set(stamps)) and stamps[-1] == last
    assert len(reports) + reports[-1].dropped_states == 1 + len(updates)
    # each report checks the supports and every brick measured up to its update, at the
    # last measured poses: as the core computes it from the same updates
    measured: dict = {}
    expect = {STAMP0: 1}
    for k, poses in enumerate(updates):
        measured.update(poses)
        expect[STAMP0 + 1 + k] = 1 + len(measured)
    assert all(r.num_blocks == expect[r.header.stamp.sec] for r in reports)
    assert all(r.status == Status.STABLE for r in reports)
    final = check_scene(scene_at_poses(design, measured))
    # the footing carries the weight of the 100 bricks (92 whole, 8 halves: 96 bricks of
    # 0.4 x 0.2 x 0.1 m at 2000 kg/m^3)
    on_footing = sum(it.resultant[2] for it in final.interfaces if it.block_a == "footing")
    assert on_footing == pytest.approx(96 * 0.4 * 0.2 * 0.1 * 2000 * 9.81, rel=1e-6)
    got = reports[-1]
    assert [(i.block_a, i.block_b) for i in got.interfaces] == \
        [(i.block_a, i.block_b) for i in final.interfaces]
    assert max(abs(a.normal_resultant - b.normal_resultant)
               for a, b in zip(got.interfaces, final.interfaces)) < 1e-6 * on_footing
    # the bag: the design once, every update, a report per answered one
    messages = list(read_bag(bag))
    topics = [m.topic for m in messages]
    assert topics.count("/rbe_node/design") == 1
    assert topics.count("/rbe_node/poses") == len(updates)
    assert topics.count("/rbe_node/report") == len(reports)
    # replayed as `rbe-ros replay --compare` (and `--live`) does, without writing a bag
    result = assert_bag_replays(bag)
    assert sum(len(r) for r in result.replayed) == len(reports)
    if live:
        live_result = assert_bag_replays(bag, recheck=live_recheck(context=rclpy_context))
        assert sum(len(r) for r in live_result.replayed) == len(reports)
    print(json.dumps({"answered": len(reports), "dropped": reports[-1].dropped_states,
                      "check_s": max(r.solve_time for r in reports)}))


def test_design_file_unknown_id_and_no_design(rclpy_context, tmp_path):
    design = gen.stack(3)
    path = tmp_path / "design.json"
    path.write_text(json.dumps(scene_to_dict(design)))
    proc = NodeProcess(["-p", f"design_file:={path}", "-p", f"mcap_path:={tmp_path / 'bag'}"],
                       tmp_path / "node.log")
    pipeline = Pipeline(rclpy_context)
    try:
        wait_until(lambda: proc.proc.poll() is None and pipeline.ready(), 60.0, "the node")
        top = design.block("b01")
        for k, poses in enumerate([
                {"b00": (design.block("b00").position.tolist(), [0, 0, 0, 1]),
                 "b01": ((top.position + [0.3, 0, 0]).tolist(), [0, 0, 0, 1])},
                {"b02": ([0, 0, 1.25], [0, 0, 0, 1]), "b7": ([0, 0, 0], [0, 0, 0, 1])},
                {"b01": ((top.position + [0.6, 0, 0]).tolist(), [0, 0, 0, 1])}]):
            pipeline.poses.publish(dict_to_message(
                poses_to_dict(poses, "", (STAMP0 + k) * 1_000_000_000), BlockPoses))
            wait_until(lambda: pipeline.report(STAMP0 + k), 30.0, f"report {k}")
        # the design's plan fails at the tipping update: its repair (in a worker process,
        # after the report) is answered before the node stops, so that the bag holds it
        wait_until(lambda: pipeline.update(STAMP0 + 2), 60.0, "the plan update")
    finally:
        pipeline.close()
        assert proc.stop() == 0
    ok, unknown, tips = (pipeline.report(STAMP0 + k) for k in range(3))
    assert ok.status == Status.STABLE and ok.num_blocks == 3
    # b01 rests on b00 with its centroid 0.3 m out: the centre of pressure is there
    it = next(i for i in ok.interfaces if {i.block_a, i.block_b} == {"b00", "b01"})
    assert it.centre_of_pressure.x == pytest.approx(0.3, abs=1e-6)
    assert unknown.status == Status.INVALID_INPUT and "'b7'" in unknown.message
    # the refused update changed nothing: b02 is not placed; b01 now 0.6 m out tips
    assert tips.status == Status.TENSION_REQUIRED and tips.num_blocks == 3
    assert tips.unstable_blocks == ["b01"]
    for recheck in ({}, {"recheck": live_recheck(context=rclpy_context)}):
        result = assert_bag_replays(tmp_path / "bag", **recheck)
        assert [len(r) for r in result.replayed] == [1] * 4   # the design, each update
