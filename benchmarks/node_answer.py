#!/usr/bin/env python3
"""The node's answer to a deviated block, over DDS: ``rbe_node`` executing the 14 x 10
dome's plan (benchmarks/repair.py's, kept by ``make bench-repair`` in build/repair/), one
pose message with the dome built to half and its last placed block off (repair.py's first
deviation), and the time from publishing it to each answer received by a plain rclpy
client: ~/report, each ~/execution and ~/plan_update. The repair runs in the node's worker
process, as in a cell; benchmarks/repair.py times the same answer in one process.

    ROS_DOMAIN_ID=N python benchmarks/node_answer.py [--runs 5] [--out docs/REPAIR_NODE.md]

Each run is a node of its own (one pose message each): the table has every run's time to
each answer, their median and the largest (the machine's other work moves single runs).
"""
from __future__ import annotations

import argparse
import json
import pickle
import statistics
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
STAMP = 100          # s, the first pose message's stamp (the answers to it carry it)
KINDS = (("report", StabilityReport), ("execution", ExecutionState),
         ("plan_update", PlanUpdate))


def one_run(client, design: Path, poses: dict, stamp: int, log: Path, wait: float
            ) -> tuple[list[tuple[float, str, object]], int | None]:
    """A node of its own executing ``design``, one pose message (stamp ``stamp`` s): each
    answer to it (s after publishing it, kind, message) and the node's exit status."""
    # the node declares the pose uncertainty itself (a design file's is not taken)
    node_process = NodeProcess(["-p", f"design_file:={design}",
                                "-p", f"pose_uncertainty_m:={UNCERTAINTY[0]}",
                                "-p", f"pose_uncertainty_deg:={UNCERTAINTY[1]}"], log)
    answers: list[tuple[float, str, object]] = []
    sent = [0.0]

    def keep(kind: str):
        def got(message):
            if message.header.stamp.sec == stamp:
                answers.append((time.monotonic() - sent[0], kind, message))
        return got

    publisher = client.create_publisher(BlockPoses, "/rbe_node/poses", RELIABLE)
    subscriptions = [client.create_subscription(
        kind_type, f"/rbe_node/{kind}", keep(kind), RELIABLE if kind == "report" else LATCHED)
        for kind, kind_type in KINDS]
    try:
        deadline = time.monotonic() + 120.0
        while (publisher.get_subscription_count() < 1
               or client.count_publishers("/rbe_node/execution") < 1):
            if time.monotonic() > deadline or node_process.proc.poll() is not None:
                print(node_process.output(), file=sys.stderr)
                return answers, None
            time.sleep(0.2)
        time.sleep(15.0)        # the design's own execution state (its look-ahead) first
        sent[0] = time.monotonic()
        publisher.publish(dict_to_message(poses_to_dict(poses, "cell", stamp * 10**9),
                                          BlockPoses))
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and not (
                any(k == "plan_update" for _, k, _ in answers)
                and answers[-1][1] == "execution"
                and answers[-1][2].first_failing_step == -1):
            time.sleep(0.1)
    finally:
        for subscription in subscriptions:
            client.destroy_subscription(subscription)
        client.destroy_publisher(publisher)
        stopped = node_process.stop()
    return answers, stopped


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "REPAIR_NODE.md")
    parser.add_argument("--wait", type=float, default=60.0, help="s to wait for the answers")
    parser.add_argument("--runs", type=int, default=5,
                        help="nodes started one after the other, one pose message each")
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
    rclpy.init()
    client = rclpy.create_node("node_answer_client")
    executor = SingleThreadedExecutor()
    executor.add_node(client)
    threading.Thread(target=executor.spin, daemon=True).start()
    runs = []
    try:
        for run in range(args.runs):
            runs.append(one_run(client, design, poses, STAMP + run, folder / f"node{run}.log",
                                args.wait))
            print(f"run {run + 1}: " + ", ".join(f"{kind} {took:.2f} s"
                                                for took, kind, _ in runs[-1][0]), flush=True)
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown()
    # the answers in the order they came (the same in every run), each run's time
    first, _ = runs[0]
    rows = []
    for i, (_, kind, m) in enumerate(first):
        what = {"report": lambda: f"stable {m.stable}",
                "execution": lambda: f"step {m.current_step}, first failing step "
                                     f"{m.first_failing_step}, {len(m.lookahead)} steps "
                                     "looked ahead",
                "plan_update": lambda: f"{m.repair}, feasible {m.feasible}, changed step "
                                       f"{m.changed_step}"}[kind]()
        times = [answers[i][0] if len(answers) > i and answers[i][1] == kind else float("nan")
                 for answers, _ in runs]
        rows.append(f"| ~/{kind} | {' | '.join(f'{t:.2f}' for t in times)} | "
                    f"{statistics.median(times):.2f} | {max(times):.2f} | {what} |")
    lines = ["# The node's answer to a deviated block, over DDS", "",
             "Made by `benchmarks/node_answer.py` (after `make bench-repair`, whose plan it "
             f"executes); machine: {machine_summary()}; {args.runs} runs, one after the "
             "other.", "",
             f"`rbe_node` with the 14 x 10 dome's plan as `design_file` (pose uncertainty "
             f"{UNCERTAINTY[0] * 1e3:g} mm / {UNCERTAINTY[1]:g} deg as parameters), one pose "
             f"message of the {len(placed)} placed blocks at design but {block}, measured 4 mm "
             "out and turned 3 deg; the time from publishing it to each answer to it "
             "(the repair in the node's worker process), a node of its own in each run. "
             "The nodes stopped with exit status "
             f"{', '.join(str(stopped) for _, stopped in runs)}.", "",
             f"| answer | {' | '.join(f'run {k + 1} s' for k in range(args.runs))} | median s "
             f"| max s | what |", "|---|" + "---|" * (args.runs + 3), *rows, ""]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))
    return 0 if rows and all(len(answers) == len(first) for answers, _ in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
