"""A plain rclpy client of a running ``rbe_node``: what a cell's own code does with it.

Start the node on a planned scene, then run this script beside it::

    rbe-ros generate semicircular-arch -p n=7 -o arch.json
    rbe-ros plan arch.json --max-held 2 -o planned.json
    rbe_node --ros-args -p design_file:=planned.json -p mcap_path:=out/run &
    python examples/node_client.py planned.json [--cell examples/cells/dome_3robots.yaml]
    rbe-ros replay out/run --compare

It publishes the planned blocks' design poses on ``~/poses`` one at a time (as a camera would
after each placement) and prints, per step, the as-built verdict on ``~/report``, the
``~/execution`` state (step, look-ahead, first failing step) and the node's ``/diagnostics``
level; then it sends bad input (an unknown block, a NaN quaternion, a malformed cell) and
prints the node's answer to each; then asks ``~/plan`` for the design (with ``--cell``, for
that robot cell). Every wait is bounded: a node that does not answer within ``--timeout``
seconds is reported, never waited for. Exit status 0 when every answer came.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose
from rbe_msgs.action import PlanSequence
from rbe_msgs.msg import AssemblyState, BlockPoses, ExecutionState, StabilityReport
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from rbe_ros.io.inputs import load_design
from rbe_ros.io.messages import state_to_dict
from rbe_ros.ros.convert import dict_to_message

STATUS = {getattr(StabilityReport, n): n for n in (
    "STABLE", "TENSION_REQUIRED", "FRICTION_EXCEEDED", "INFEASIBLE", "SOLVER_FAILED",
    "INVALID_INPUT", "HOLD_EXCEEDED")}
LEVEL = {b"\x00": "OK", b"\x01": "WARN", b"\x02": "ERROR", b"\x03": "STALE"}
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
# ~/report and ~/execution are latched (transient_local): a late subscriber gets the last one.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class RbeClient:
    """Publishes poses, keeps every report, execution state and diagnostics it receives."""

    def __init__(self, node_name: str):
        self.node = Node("rbe_example_client")
        self.cond = threading.Condition()
        self.reports: list[StabilityReport] = []
        self.executions: list[ExecutionState] = []
        self.diagnostics: str = "none yet"
        base = f"/{node_name}"
        self.poses = self.node.create_publisher(BlockPoses, f"{base}/poses", RELIABLE)
        self.node.create_subscription(StabilityReport, f"{base}/report",
                                      self._keep(self.reports), LATCHED)
        self.node.create_subscription(ExecutionState, f"{base}/execution",
                                      self._keep(self.executions), LATCHED)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.plan = ActionClient(self.node, PlanSequence, f"{base}/plan")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _keep(self, store: list):
        def callback(msg):
            with self.cond:
                store.append(msg)
                self.cond.notify_all()
        return callback

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith("rbe_node") or "rbe" in status.name:
                level = LEVEL.get(bytes(status.level) if isinstance(status.level, bytes)
                                  else bytes([status.level]), str(status.level))
                self.diagnostics = f"{level} ({status.message})"

    def wait(self, store: list, stamp: int, timeout: float):
        """The first message of ``store`` with header stamp ``stamp`` (s), or None."""
        end = time.monotonic() + timeout
        with self.cond:
            while True:
                found = [m for m in store if m.header.stamp.sec == stamp]
                if found:
                    return found[-1]
                if time.monotonic() > end:
                    return None
                self.cond.wait(max(end - time.monotonic(), 0.0))

    def send_poses(self, stamp: int, poses: dict[str, tuple]) -> None:
        msg = BlockPoses()
        msg.header.frame_id = "world"
        msg.header.stamp.sec = stamp
        for block_id, (p, q) in poses.items():
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = map(float, p)
            (pose.orientation.x, pose.orientation.y, pose.orientation.z,
             pose.orientation.w) = map(float, q)
            msg.ids.append(block_id)
            msg.poses.append(pose)
        self.poses.publish(msg)

    def _in_executor(self, fn, timeout: float):
        """``fn()``'s result, run by the executor thread (rclpy's ActionClient is not
        thread-safe: a goal sent from another thread may lose its response); None on time-out."""
        return _done(self.executor.create_task(fn), timeout)

    def plan_result(self, goal, feedback: list, timeout: float):
        """The result of a ~/plan goal (feedback appended to ``feedback``); None when it was
        refused or did not come within ``timeout`` s."""
        sent = self._in_executor(lambda: self.plan.send_goal_async(
            goal, feedback_callback=lambda m: feedback.append(m.feedback)), timeout)
        handle = sent and _done(sent, timeout)
        if handle is None or not handle.accepted:
            return None
        response = _done(self._in_executor(handle.get_result_async, timeout), timeout)
        return response and response.result

    def wait_subscribed(self, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while self.poses.get_subscription_count() < 1 or not self.plan.server_is_ready():
            if time.monotonic() > end:
                return False
            time.sleep(0.1)
        return True


def _done(future, timeout: float):
    """The future's result, None when it is not done within ``timeout`` s."""
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    return future.result() if future.done() or done.wait(timeout) else None


def report_line(report: StabilityReport | None) -> str:
    """A report in one line: its verdict and message."""
    if report is None:
        return "NO REPORT (timed out)"
    return f"{STATUS.get(report.status, report.status)}: {report.message[:150]}"


def execution_line(state: ExecutionState | None) -> str:
    """An execution state in one line: step, as-built verdict, look-ahead, why."""
    if state is None:
        return "NO EXECUTION STATE (timed out)"
    failing = "none" if state.first_failing_step < 0 else state.first_failing_step
    as_built = STATUS.get(state.as_built.status, state.as_built.status)
    text = (f"active {state.active}, step {state.current_step}/{state.total_steps}, "
            f"as built (the plan's holds) {as_built}, "
            f"look-ahead {len(state.lookahead)} steps, first failing {failing}")
    return text + (f", message: {state.message[:150]}" if state.message else "")


def main(argv=None) -> int:
    """Drive the node as the module's docstring says; 0 when every answer came."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("planned", help="the planned scene the node was started with (design_file)")
    ap.add_argument("--node-name", default="rbe_node")
    ap.add_argument("--cell", help="a robot cell file for the ~/plan goal")
    ap.add_argument("--plan-time-limit", type=float, default=60.0, help="s, the goal's limit")
    ap.add_argument("--timeout", type=float, default=30.0, help="s to wait for each answer")
    args = ap.parse_args(argv)

    scene, _ = load_design(Path(args.planned))
    blocks = {b.id: b for b in scene.blocks}
    rclpy.init()
    client = RbeClient(args.node_name)
    missing = 0
    try:
        if not client.wait_subscribed(args.timeout):
            print(f"no {args.node_name} with ~/poses and ~/plan within {args.timeout} s")
            return 1
        measured: dict[str, tuple] = {}
        for k, block_id in enumerate(scene.sequence):
            b = blocks[block_id]
            measured[block_id] = (b.position, b.orientation)
            client.send_poses(k + 1, {block_id: measured[block_id]})
            report = client.wait(client.reports, k + 1, args.timeout)
            execution = client.wait(client.executions, k + 1, args.timeout)
            missing += report is None or execution is None
            print(f"step {k} {block_id}: {report_line(report)}")
            print(f"    execution: {execution_line(execution)}")
            print(f"    /diagnostics: {client.diagnostics}")

        stamp = 1000
        bad = {"an unknown block": {"no_such_block": ((0, 0, 1), (0, 0, 0, 1))},
               "a NaN quaternion": {scene.sequence[0]: (blocks[scene.sequence[0]].position,
                                                        (math.nan, 0, 0, 1))}}
        for what, poses in bad.items():
            stamp += 1
            t0 = time.monotonic()
            client.send_poses(stamp, poses)
            report = client.wait(client.reports, stamp, args.timeout)
            execution = client.wait(client.executions, stamp, args.timeout)
            missing += report is None
            print(f"bad poses, {what}: answered in {time.monotonic() - t0:.2f} s: "
                  f"{report_line(report)}")
            print(f"    execution: {execution_line(execution)}")

        design = dict_to_message(state_to_dict(scene, "world", 0), AssemblyState)
        goals = {"a malformed cell": PlanSequence.Goal(assembly=design, max_held=2,
                                                       cell="robots: [{name: r1, reach: }",
                                                       time_limit=args.plan_time_limit)}
        unknown = dict_to_message(state_to_dict(scene, "world", 0), AssemblyState)
        unknown.sequence = [*unknown.sequence[:1], "no_such_block"]
        goals["a sequence naming an unknown block"] = PlanSequence.Goal(
            assembly=unknown, max_held=2, time_limit=args.plan_time_limit)
        cell = Path(args.cell).read_text() if args.cell else ""
        goals[f"the design{' for ' + args.cell if cell else ''}"] = PlanSequence.Goal(
            assembly=design, max_held=2, cell=cell, time_limit=args.plan_time_limit)
        for what, goal in goals.items():
            t0 = time.monotonic()
            feedback: list = []
            result = client.plan_result(goal, feedback, args.plan_time_limit + args.timeout)
            took = time.monotonic() - t0
            if result is None:
                missing += 1
                print(f"~/plan, {what}: NO RESULT within the time limit")
                continue
            print(f"~/plan, {what}: {took:.1f} s, {len(feedback)} feedback messages, "
                  f"feasible {result.feasible}: {result.message[:200]}")
            if result.feasible:
                print(f"    order {list(result.order)}; {len(result.timeline)} robot actions "
                      f"of {list(result.robots)}")
        print(json.dumps({"unanswered": missing}))
        return 1 if missing else 0
    finally:
        client.executor.shutdown(timeout_sec=5.0)
        client.thread.join(5.0)
        client.plan.destroy()
        client.node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
