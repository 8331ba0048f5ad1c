#!/usr/bin/env python3
"""The node's answer to a deviated block, over DDS: ``rbe_node`` executing the 14 x 10
dome's plan (benchmarks/repair.py's, kept by ``make bench-repair`` in build/repair/), one
pose message with the dome built to half and its last placed block off (repair.py's first
deviation), and the time from publishing it to each answer received by a plain rclpy
client: ~/report, each ~/execution and ~/plan_update. The repair runs in the node's worker
process, as in a cell; benchmarks/repair.py times the same answer in one process.

    ROS_DOMAIN_ID=N python benchmarks/node_answer.py [--out docs/REPAIR_NODE.md]
"""
from __future__ import annotations

import argparse
import json
import pickle
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
from rbe_msgs.msg import BlockPoses, ExecutionState, PlanUpdate, StabilityReport
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from machine import machine_summary
from repair import UNCERTAINTY, half_built
from trees import PLAN, ROOT

from rbe_ros.io.messages import poses_to_dict
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.ros.convert import dict_to_message
from rbe_ros.ros.live import NodeProcess

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STAMP = 100          # s, the pose message's stamp (the answers to it carry it)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "REPAIR_NODE.md")
    parser.add_argument("--wait", type=float, default=60.0, help="s to wait for the answers")
    args = parser.parse_args()
    if not PLAN.exists():
        print(f"no plan at {PLAN}: run make bench-repair first", file=sys.stderr)
        return 1
    plan, _ = pickle.load(open(PLAN, "rb"))
    block, built = half_built(plan, 0)
    placed = plan.order[:len(plan.order) // 2]
    poses = {b: (built.block(b).position.tolist(), list(built.block(b).orientation))
             for b in placed}
    folder = Path(tempfile.mkdtemp(prefix="node_answer_"))
    design = folder / "planned.json"
    design.write_text(json.dumps(scene_to_dict(plan.scene)))
    # the node declares the pose uncertainty itself (a design file's is not taken)
    node_process = NodeProcess(["-p", f"design_file:={design}",
                                "-p", f"pose_uncertainty_m:={UNCERTAINTY[0]}",
                                "-p", f"pose_uncertainty_deg:={UNCERTAINTY[1]}"],
                               folder / "node.log")
    rclpy.init()
    client = rclpy.create_node("node_answer_client")
    answers: list[tuple[float, str, object]] = []
    sent = [0.0]

    def keep(kind: str):
        def got(message):
            if message.header.stamp.sec == STAMP:
                answers.append((time.monotonic() - sent[0], kind, message))
        return got

    publisher = client.create_publisher(BlockPoses, "/rbe_node/poses", RELIABLE)
    client.create_subscription(StabilityReport, "/rbe_node/report", keep("report"), RELIABLE)
    client.create_subscription(ExecutionState, "/rbe_node/execution", keep("execution"),
                               LATCHED)
    client.create_subscription(PlanUpdate, "/rbe_node/plan_update", keep("plan_update"),
                               LATCHED)
    executor = SingleThreadedExecutor()
    executor.add_node(client)
    threading.Thread(target=executor.spin, daemon=True).start()
    try:
        deadline = time.monotonic() + 120.0
        while (publisher.get_subscription_count() < 1
               or client.count_publishers("/rbe_node/execution") < 1):
            if time.monotonic() > deadline or node_process.proc.poll() is not None:
                print(node_process.output(), file=sys.stderr)
                return 1
            time.sleep(0.2)
        time.sleep(15.0)        # the design's own execution state (its look-ahead) first
        sent[0] = time.monotonic()
        publisher.publish(dict_to_message(poses_to_dict(poses, "cell", STAMP * 10**9),
                                          BlockPoses))
        deadline = time.monotonic() + args.wait
        while time.monotonic() < deadline and not (
                any(k == "plan_update" for _, k, _ in answers)
                and answers[-1][1] == "execution"
                and answers[-1][2].first_failing_step == -1):
            time.sleep(0.1)
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown()
        stopped = node_process.stop()
    rows = []
    for took, kind, m in answers:
        what = {"report": lambda: f"stable {m.stable}",
                "execution": lambda: f"step {m.current_step}, first failing step "
                                     f"{m.first_failing_step}, {len(m.lookahead)} steps "
                                     "looked ahead",
                "plan_update": lambda: f"{m.repair}, feasible {m.feasible}, changed step "
                                       f"{m.changed_step}"}[kind]()
        rows.append(f"| ~/{kind} | {took:.2f} | {what} |")
    lines = ["# The node's answer to a deviated block, over DDS", "",
             "Made by `benchmarks/node_answer.py` (after `make bench-repair`, whose plan it "
             "executes); machine: " + machine_summary() + "; one run.", "",
             f"`rbe_node` with the 14 x 10 dome's plan as `design_file` (pose uncertainty "
             f"{UNCERTAINTY[0] * 1e3:g} mm / {UNCERTAINTY[1]:g} deg as parameters), one pose "
             f"message of the {len(placed)} placed blocks at design but {block}, measured 4 mm "
             "out and turned 3 deg; the time from publishing it to each answer to it "
             "(the repair in the node's worker process). The node stopped with exit status "
             f"{stopped}.", "",
             "| answer | s after the pose message | what |", "|---|---|---|", *rows, ""]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0 if rows else 1


if __name__ == "__main__":
    sys.exit(main())
