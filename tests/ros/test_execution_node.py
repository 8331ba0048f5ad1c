"""Executing a planned structure from a simulated camera over DDS (~/poses -> ~/execution,
~/plan_update): a block lands off so that a later step of the plan would fall; the node says
which step within 2 s, repairs the rest of the plan, the repaired plan stands at the
measured poses (re-checked here by a closed form and by ``rbe-ros check``), and the bag
replays with ``--compare``."""
from __future__ import annotations

import json
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
from rbe_msgs.msg import BlockPoses, ExecutionState, PlanUpdate
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from scipy.spatial.transform import Rotation

from helpers import ONE_ROBOT, overhang_stack, stack_stands
from rbe_client import NodeProcess, wait_until
from rbe_ros import cli
from rbe_ros.io.bag import read_bag
from rbe_ros.io.messages import poses_to_dict
from rbe_ros.io.replay import compare_execution
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.io.testing import assert_bag_replays
from rbe_ros.rbe.result import Status
from rbe_ros.ros.convert import dict_to_message, message_to_dict
from rbe_ros.scene import Hold, box_block, make_block, make_scene

NAMESPACE = "/rbe_execution_test"
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
DENSITY = 2000.0
STAMP0 = 70_000


def plank(counterweight_height: float, robots: int = 0, mid: bool = False):
    """A plank on a narrow pier (0.3 m deep), a block to go on its left end, then one on its
    right end (the counterweight). Left first leans the plank 5 mm inside the pier's edge:
    near the limit (its centroid 60 mm out, the edge at 65 mm). With a counterweight as tall
    as the left block either order stands at design; a twice as tall one tips the plank
    right if placed first (so the plan is left, right). ``mid``: a block placed first in the
    middle of the plank, the pier narrower to keep left first 3.5 mm inside its edge (the
    step that an offset plank fails is then one step further ahead). ``robots`` 1: a robot
    steadies the plank while it is set down (step 0), so the cell has one robot to hold a
    block with (K = 1) later too."""
    h = counterweight_height
    blocks = [box_block("pier", (0.116 if mid else 0.13, 0.3, 0.5), (0, 0, 0.25),
                        support=True, density=DENSITY),
              box_block("plank", (0.8, 0.3, 0.1), (0, 0, 0.55), density=DENSITY),
              *([box_block("mid", (0.1, 0.3, 0.1), (0, 0, 0.65), density=DENSITY)]
                if mid else []),
              box_block("left", (0.2, 0.3, 0.1), (-0.3, 0, 0.65), density=DENSITY),
              box_block("right", (0.2, 0.3, h), (0.3, 0, 0.6 + h / 2), density=DENSITY)]
    return make_scene("plank", blocks,
                      sequence=["plank", *(["mid"] if mid else []), "left", "right"],
                      holds=[Hold("plank", 0, 1)] if robots else [])


def pier(design) -> np.ndarray:
    """The half-widths (m) in x and y of the pier's top (centred on the origin)."""
    return np.ptp(design.block("pier").vertices, axis=0)[:2] / 2


def stands(design, poses: dict, free: list[str]) -> bool:
    """Closed form (the oracle): the plank and the blocks on it, all free, stand on the pier
    iff their common centroid lies over the pier's top rectangle (every block a box of one
    density: centroid = volume-weighted mean of the measured positions)."""
    volume = {b.id: float(np.prod(np.ptp(b.vertices, axis=0))) for b in design.blocks}
    weights = np.array([volume[b] for b in free])
    centre = (weights[:, None] * np.array([poses[b][0] for b in free])).sum(0) / weights.sum()
    return bool(np.all(np.abs(centre[:2]) < pier(design)))


class Camera:
    """The cell's side: streams the measured pose of each block as it is placed (0.5 mm
    noise, seeded) and keeps what comes on ~/execution and ~/plan_update."""

    def __init__(self, context, seed: int):
        self.node = Node("rbe_camera", context=context)
        self.poses = self.node.create_publisher(BlockPoses, "/rbe_node/poses", RELIABLE)
        self.states: list[tuple[float, ExecutionState]] = []
        self.updates: list[PlanUpdate] = []
        self.lock = threading.Lock()
        self.node.create_subscription(ExecutionState, "/rbe_node/execution", self._state,
                                      LATCHED)
        self.node.create_subscription(PlanUpdate, "/rbe_node/plan_update", self._update,
                                      LATCHED)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.rng = np.random.default_rng(seed)
        self.sent: dict[int, float] = {}        # stamp sec -> time sent
        self.measured: dict[str, tuple] = {}

    def _state(self, msg):
        with self.lock:
            self.states.append((time.monotonic(), msg))

    def _update(self, msg):
        with self.lock:
            self.updates.append(msg)

    def ready(self) -> bool:
        return self.poses.get_subscription_count() >= 1 and \
            self.node.count_publishers("/rbe_node/execution") >= 1

    def place(self, design, block: str, sec: int, offset=(0.0, 0.0, 0.0), yaw_deg=0.0):
        """The block lands at its design pose moved by ``offset`` (m) and turned by
        ``yaw_deg`` about the vertical; measured with 0.5 mm noise in x and y."""
        b = design.block(block)
        noise = np.r_[self.rng.normal(0.0, 0.0005, 2), 0.0]
        q = (Rotation.from_euler("z", yaw_deg, degrees=True) *
             Rotation.from_quat(b.orientation)).as_quat()
        self.measured[block] = ((b.position + offset + noise).tolist(), q.tolist())
        self.sent[sec] = time.monotonic()
        self.poses.publish(dict_to_message(poses_to_dict(
            {block: self.measured[block]}, "cell", sec * 1_000_000_000), BlockPoses))

    def state(self, sec: int, last: bool = False):
        """The (first, or ``last``) ExecutionState answering the poses of ``sec``."""
        with self.lock:
            found = [(t, m) for t, m in self.states if m.header.stamp.sec == sec]
        return (found[-1] if last else found[0]) if found else None

    def close(self):
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(5.0)
        self.node.destroy_node()


def rbe_check(capsys, path, poses: dict, tmp_path, name: str, sequence: bool = False) -> dict:
    """``rbe-ros check PATH --poses`` (``--sequence``) as a user runs it (its main, in this
    process): its JSON."""
    file = tmp_path / f"{name}.json"
    file.write_text(json.dumps({"poses": {b: {"position": p, "orientation": q}
                                          for b, (p, q) in poses.items()}}))
    args = ["--poses", str(file)] if poses else []
    capsys.readouterr()
    assert cli.main(["check", str(path), *args, "--json",
                     *(["--sequence"] if sequence else [])]) == 0
    return json.loads(capsys.readouterr().out)


def cell_plan_file(design, cell: dict, path) -> dict:
    """The plan of ``design`` in its order for ``cell``, written as ``rbe-ros plan --cell -o``
    writes it (the planned scene, the cell, the timeline); the file's JSON."""
    from rbe_ros.analysis.options import CheckOptions
    from rbe_ros.analysis.planning import plan_sequence
    from rbe_ros.cell import cell_from_dict
    from rbe_ros.io.plan_export import plan_export

    plan = plan_sequence(design, 0, CheckOptions(), cell=cell_from_dict(cell),
                         keep_sequence=True)
    assert plan.feasible and plan.order == list(design.sequence), plan.message
    doc = plan_export(plan, CheckOptions())
    path.write_text(json.dumps(doc))
    return doc


#: The two structures executed: the block that lands off (after the blocks before it, at
#: design), how, and the look-ahead's (current step, first failing step) then.
CASES = {
    # a stack near its overhang limit, planned for one robot: s2 lands 10 mm out and turned
    # 2 deg; s3 next would tip s2 and s3 over s1's edge; no robot is free to hold: only the
    # order (the counterweight first) saves it
    "stack": dict(design=overhang_stack, cell=ONE_ROBOT, stands=stack_stands, before=["s1"],
                  block="s2", offset=[0.01, 0.0, 0.0], failing=(2, 2), next_block="s3",
                  repair="swap"),
    # a plank on a pier with a robot to hold (K = 1): the plank lands 10 mm left and turned
    # 2 deg; the middle block next stands, the left one after it would tip the plank; no
    # order does: only a hold
    "plank": dict(design=lambda: plank(0.2, 1, mid=True), cell=None, stands=stands,
                  before=[], block="plank", offset=[-0.01, 0.0, 0.0], failing=(1, 2),
                  next_block="left", repair="hold"),
}


@pytest.mark.long       # 10-15 s each: a node, its repair process, a replay
@pytest.mark.parametrize("case", list(CASES))
def test_block_lands_off_a_later_step_fails_and_the_plan_is_repaired(
        rclpy_context, tmp_path, capsys, case):
    c = CASES[case]
    design = c["design"]()
    path = tmp_path / "planned.json"
    if c["cell"] is not None:
        planned = cell_plan_file(design, c["cell"], path)
    else:
        path.write_text(json.dumps(scene_to_dict(design)))
    at_design = {b.id: (b.position.tolist(), list(b.orientation)) for b in design.blocks
                 if not b.support}
    off = {c["block"]: ((design.block(c["block"]).position + c["offset"]).tolist(),
                        Rotation.from_euler("z", 2, degrees=True).as_quat().tolist())}
    order = list(design.sequence)
    k_off = order.index(c["block"])
    failing_step = c["failing"][1]
    # the oracle: as designed every step stands; with the block off the failing step
    # falls, the steps before it and the whole stand
    for k in range(len(order)):
        assert c["stands"](design, at_design, order[:k + 1])
    measured = {**at_design, **off}
    assert c["stands"](design, measured, order[:failing_step])
    assert not c["stands"](design, measured, order[:failing_step + 1])
    assert c["stands"](design, measured, order)
    # and `rbe-ros check` of the failing step's state (the block off, the others at design)
    check = rbe_check(capsys, path, {b: measured[b] for b in order[:failing_step + 1]},
                      tmp_path, "failing_next")
    assert check["stable"] is False and check["status"] == 1      # TENSION_REQUIRED
    # which orders of the blocks left stand without a hold (the oracle)
    rest = order[failing_step:]
    saving = [o for o in ([rest[1], rest[0], *rest[2:]],)
              if all(c["stands"](design, measured, order[:failing_step] + o[:j + 1])
                     for j in range(len(o)))]
    assert bool(saving) == (c["repair"] == "swap")

    bag = tmp_path / "bag"
    proc = NodeProcess(["-p", f"design_file:={path}", "-p", f"mcap_path:={bag}"],
                       tmp_path / "node.log")
    camera = Camera(rclpy_context, seed=30)
    try:
        wait_until(lambda: proc.proc.poll() is None and camera.ready(), 60.0, "the node")
        wait_until(lambda: camera.states, 30.0, "the design's execution state")
        start = camera.states[-1][1]
        assert (start.active, start.current_step, start.total_steps) == (True, 0, len(order))
        assert start.first_failing_step == -1 and [s.block for s in start.lookahead] == order
        sec = STAMP0
        for block in c["before"]:
            camera.place(design, block, sec)
            wait_until(lambda: camera.state(sec), 30.0, f"{block}")
            sec += 1
        camera.place(design, c["block"], sec, offset=c["offset"], yaw_deg=2.0)
        received, failing = wait_until(lambda: camera.state(sec), 30.0, "execution")
        assert received - camera.sent[sec] < 2.0
        # a later step fails: the look-ahead says so now
        assert (failing.current_step, failing.first_failing_step) == c["failing"]
        assert [(s.block, s.stable) for s in failing.lookahead][
            failing_step - failing.current_step] == (c["next_block"], False)
        assert f"step {failing_step} ({c['next_block']})" in failing.message
        if c["cell"] is None:   # it goes out at the failing step (a cell's: the window)
            assert failing.lookahead[-1].step == failing_step
        update = wait_until(lambda: camera.updates, 60.0, "the plan update")[0]
        assert update.feasible and update.changed_step == failing_step
        assert list(update.order[:failing_step]) == order[:failing_step]
        assert update.reason.startswith(f"step {failing_step} ({c['next_block']}) fails at "
                                        "the measured poses")
        assert update.repair == c["repair"]
        # the repaired plan's execution state: nothing fails ahead any more
        repaired = wait_until(lambda: len([m for _, m in camera.states
                                           if m.header.stamp.sec == sec]) >= 2
                              and camera.state(sec, True), 30.0, "the repaired plan's state")[1]
        assert repaired.first_failing_step == -1 and repaired.active
        new_order = list(update.order)
        holds = [message_to_dict(h) for h in update.holds]
        if c["cell"] is not None:
            # the cell's plan: the repaired timeline (the robot places each block in the new
            # order), beside the timeline of the file it started from
            assert [a.block for a in update.timeline if a.action == "place"] == new_order
            assert {a.robot for a in update.timeline} == {"r1"}
            assert all(a.stable for a in update.timeline if a.step >= failing_step)
            assert [a["block"] for a in planned["timeline"] if a["action"] == "place"] == order
        else:
            assert not update.timeline
        # the camera follows the repaired plan
        for k, block in enumerate(new_order[k_off + 1:], start=k_off + 1):
            camera.place(design, block, sec + k)
            got = wait_until(lambda: camera.state(sec + k, True), 30.0, f"step {k}")[1]
            assert got.current_step == k + 1 and got.first_failing_step == -1
    finally:
        camera.close()
        assert proc.stop() == 0
    log = proc.output()
    assert "Traceback" not in log and "plan repaired" in log

    # every remaining step of the repaired plan stands at the measured poses: a held block
    # is a support (the plank then rests on the pier and it); the oracle on the free ones
    measured = camera.measured
    for k in range(k_off, len(new_order)):
        held = {h["block"] for h in holds if h["from_step"] <= k and
                (h["until_step"] < 0 or k < h["until_step"])}
        assert held or c["stands"](design, measured, new_order[:k + 1]), f"step {k}"
    if c["repair"] == "hold":
        assert holds, "no order stands: the repair must hold a block"
    else:
        assert new_order[failing_step:] in saving and not holds
    # and by `rbe-ros check --sequence` on the repaired plan, its blocks at the measured poses
    # (--poses would drop the holds: they count the design's steps)
    repaired_path = tmp_path / "repaired.json"
    doc = scene_to_dict(replace(design, blocks=tuple(
        make_block(b.id, b.vertices, b.faces, *measured.get(b.id, (b.position, b.orientation)),
                   density=DENSITY, support=b.support) for b in design.blocks)))
    doc["sequence"] = new_order
    doc["holds"] = [{"block": h["block"], "from_step": h["from_step"],
                     **({"until_step": h["until_step"]} if h["until_step"] >= 0 else {})}
                    for h in holds]
    repaired_path.write_text(json.dumps(doc))
    steps = rbe_check(capsys, repaired_path, {}, tmp_path, "all", sequence=True)
    assert [r["stable"] for r in steps["reports"]] == [True] * len(steps["reports"]), steps
    assert len(steps["reports"]) >= len(new_order)
    # the bag: every execution state and the update recorded, and `replay --compare`
    topics = [m.topic for m in read_bag(bag)]
    assert topics.count("/rbe_node/plan_update") == 1
    assert topics.count("/rbe_node/execution") >= len(new_order) + 2
    result = assert_bag_replays(bag)
    assert sum(len(r.execution) for r in result.runs) == topics.count("/rbe_node/execution") + 1


def test_bad_poses_give_a_reason_keep_the_state_and_the_bag(make_node, tmp_path):
    """A block measured out of the plan's order, a block not in the design, a design that
    does not match the plan: ~/execution says why (inactive, the step reached kept), the
    as-built checks go on, every message is in the bag, and the bag replays."""
    from rclpy.serialization import serialize_message

    from rbe_msgs.msg import AssemblyState
    from rbe_ros.io.messages import state_to_dict

    design = plank(0.1)
    path = tmp_path / "planned.json"
    path.write_text(json.dumps(scene_to_dict(design)))
    node = make_node(design_file=str(path), mcap_path=str(tmp_path / "bag"))
    states: list[dict] = []
    node._send_execution = (lambda send: lambda kind, m: (states.append((kind, m)),
                                                          send(kind, m)))(node._send_execution)

    def poses(sec: int, measured: dict) -> None:
        node._on_poses(serialize_message(dict_to_message(
            poses_to_dict(measured, "cell", sec * 1_000_000_000), BlockPoses)))
        wait_until(lambda: any(m["header"]["stamp"]["sec"] == sec for _, m in states), 30.0,
                   f"the execution state of {sec}")

    at = {b.id: (b.position.tolist(), [0, 0, 0, 1]) for b in design.blocks}
    poses(1, {"plank": at["plank"]})
    poses(2, {"right": at["right"]})                 # the plan places left first
    poses(3, {"ghost": at["left"]})                  # not in the design
    poses(4, {"left": at["left"]})                   # now in order again
    other = make_scene("other", [design.block("pier"), design.block("plank")])
    node._on_design(serialize_message(dict_to_message(state_to_dict(other, "cell", 5 * 10**9),
                                                      AssemblyState)))
    wait_until(lambda: any(m["header"]["stamp"]["sec"] == 5 for _, m in states), 30.0, "5")
    node.destroy_node()
    by_sec = {m["header"]["stamp"]["sec"]: m for kind, m in states if kind == "execution"}
    assert by_sec[1]["active"] and by_sec[1]["current_step"] == 1
    wrong = by_sec[2]
    assert not wrong["active"] and wrong["current_step"] == 1 and wrong["message"] == (
        "measured blocks are not a prefix of the plan's order: 'right' (step 2) is measured "
        "but 'left' (step 1) is not")
    # the as-built state is checked as measured all the same (the counterweight alone holds)
    assert wrong["as_built"]["status"] == 0 and wrong["as_built"]["num_blocks"] == 3
    ghost = by_sec[3]
    assert not ghost["active"] and ghost["current_step"] == 1
    assert ghost["message"].startswith("poses not accepted: measured poses name a block not "
                                       "in the design") and "'ghost'" in ghost["message"]
    assert ghost["as_built"]["status"] == 5          # INVALID_INPUT; nothing merged
    done = by_sec[4]
    assert done["active"] and done["current_step"] == 3 and done["as_built"]["status"] == 0
    assert not by_sec[5]["active"] and by_sec[5]["message"] == (
        "the plan 'plank' does not match the design 'cell': blocks 'left', 'right' are in "
        "only one")
    topics = [m.topic.rsplit("/", 1)[1] for m in read_bag(tmp_path / "bag")]
    assert topics.count("poses") == 4 and topics.count("design") == 2
    assert topics.count("execution") == len(states)
    result = assert_bag_replays(tmp_path / "bag")
    assert result.executed == len(states)
    # a recorded state the replay does not make again is a difference
    run = next(r for r in result.runs if r.execution)
    kind, recorded = run.execution[0]
    run.execution[0] = (kind, {**recorded, "current_step": recorded["current_step"] + 1})
    [found] = compare_execution(0, run, [(kind, recorded)])
    assert (found.where, found.field) == ("execution", "current_step")


@pytest.mark.long
def test_checks_keep_their_latency_while_a_plan_runs(rclpy_context, tmp_path):
    """A plan runs in a worker process (lower priority): the as-built checks a cell waits on
    keep their latency, within 1.2x of that without a plan, in one run (was about 1.7x with
    the plan in the node's process)."""
    from rbe_ros import generators

    from rbe_client import Client, state_msg
    from rbe_msgs.action import PlanSequence

    wall = replace(generators.running_bond_wall(10, 15), sequence=())
    proc = NodeProcess([], tmp_path / "node.log")
    client = Client(rclpy_context, markers=False)

    def latencies(count: int, start: int) -> list[float]:
        out = []
        for k in range(count):
            # a brick 0.1 mm further out each time: a new state, checked afresh
            moved = replace(wall, blocks=tuple(
                make_block(b.id, b.vertices, b.faces, b.position + [0, 1e-4 * k, 0]
                           if b.id == wall.blocks[-1].id else b.position, b.orientation,
                           density=b.density, support=b.support) for b in wall.blocks))
            state = state_msg(moved, "wall")
            state.header.stamp.sec = start + k
            sent = time.monotonic()
            client.publish(state)
            client.report_for(state, timeout=60.0)
            out.append(time.monotonic() - sent)
            time.sleep(0.3)
        return out

    try:
        client.wait_ready(proc, 60.0)
        latencies(2, 10)                                 # warm up
        alone = latencies(8, 100)
        feedback: list = []
        handle = client.send_plan(PlanSequence.Goal(assembly=state_msg(generators.dome()),
                                                    max_held=2), feedback)
        wait_until(lambda: feedback, 120.0, "the plan running")
        planning = latencies(8, 200)
        running = len(feedback)
        client.cancel(handle)
        client.result(handle, timeout=120.0)
        after = latencies(8, 300)
    finally:
        client.close()
        assert proc.stop() == 0
    assert running >= 2                                  # the plan went on meanwhile
    ratio = float(np.median(planning) / np.median(alone + after))
    print(json.dumps({"median_alone_s": float(np.median(alone + after)),
                      "median_planning_s": float(np.median(planning)), "ratio": ratio,
                      "steps_planned_meanwhile": running}))
    assert ratio <= 1.2


def test_a_plan_of_the_node_is_the_plan_executed(make_node, tmp_path):
    """A feasible ~/plan result of the design, with nothing measured yet, is the plan
    ~/execution follows (sent on as the design: recorded, replayed); without a design, or
    once blocks are measured, a plan is not taken."""
    from rclpy.serialization import serialize_message

    from rbe_msgs.msg import AssemblyState
    from rbe_ros.analysis.planning import plan_sequence
    from rclpy.parameter import Parameter

    from rbe_ros.io.messages import scene_from_state_dict, state_to_dict

    # as the node has them: the design and the goal's assembly both came as messages
    design = scene_from_state_dict(state_to_dict(replace(plank(0.1), sequence=())))
    plan = plan_sequence(design, 0)
    assert plan.feasible and plan.order[0] == "plank"
    node = make_node(mcap_path=str(tmp_path / "bag"))
    states: list[dict] = []
    node._send_execution = (lambda send: lambda kind, m: (states.append(m), send(kind, m)))(
        node._send_execution)
    node._adopt(plan, {"frame_id": "cell", "stamp": {"sec": 0, "nanosec": 0}})   # no design
    node._on_design(serialize_message(dict_to_message(state_to_dict(design, "cell", 10**9),
                                                      AssemblyState)))
    node._adopt(plan, {"frame_id": "cell", "stamp": {"sec": 0, "nanosec": 0}})
    wait_until(lambda: states, 30.0, "the plan's execution state")
    assert states[-1]["active"] and states[-1]["current_step"] == 0
    assert [s["block"] for s in states[-1]["lookahead"]] == plan.order
    b = design.block("plank")
    node._on_poses(serialize_message(dict_to_message(poses_to_dict(
        {"plank": (b.position.tolist(), [0, 0, 0, 1])}, "cell", 10**10), BlockPoses)))
    state = wait_until(lambda: next((m for m in states
                                     if m["header"]["stamp"]["sec"] == 10), None), 30.0, "10")
    assert state["active"] and state["current_step"] == 1 and state["first_failing_step"] == -1
    assert [s["block"] for s in state["lookahead"]] == plan.order[1:]
    # a run-time change of lookahead_steps (recorded with the settings: replayed so)
    assert node.set_parameters([Parameter("lookahead_steps", value=1)])[0].successful
    node._on_poses(serialize_message(dict_to_message(poses_to_dict(
        {"plank": (b.position.tolist(), [0, 0, 0, 1])}, "cell", 11 * 10**9), BlockPoses)))
    state = wait_until(lambda: next((m for m in states
                                     if m["header"]["stamp"]["sec"] == 11), None), 30.0, "11")
    assert [s["block"] for s in state["lookahead"]] == plan.order[1:2]
    node._adopt(plan, {"frame_id": "cell", "stamp": {"sec": 0, "nanosec": 0}})  # not taken
    node.destroy_node()
    topics = [m.topic.rsplit("/", 1)[1] for m in read_bag(tmp_path / "bag")]
    assert topics.count("design") == 2                   # the design, then the plan of it
    assert_bag_replays(tmp_path / "bag")



def test_a_step_ahead_below_min_margin_g_is_repaired(make_node, tmp_path):
    """min_margin_g: a step ahead that stands with less margin fails, and the plan is
    repaired. The left block's step tips the plank at 0.0714 g: the closed form of tipping
    about the pier's edge, the centroid 5 mm inside it and 70 mm above its top."""
    design = plank(0.2, robots=1)
    path = tmp_path / "planned.json"
    path.write_text(json.dumps(scene_to_dict(design)))
    states: list[tuple[str, dict]] = []
    node = make_node(design_file=str(path), mcap_path=str(tmp_path / "bag"), min_margin_g=0.1)
    node._send_execution = (lambda send: lambda kind, m: (states.append((kind, m)),
                                                          send(kind, m)))(node._send_execution)
    state, name = node.design_message(str(path))
    node._send_design(state, name=name)                 # as at start, now observed
    wait_until(lambda: len(states) >= 3, 60.0, "the design's state, update and state")
    node.destroy_node()
    (_, first), (kind, update), (_, repaired) = states[:3]
    volume = {"plank": 0.8 * 0.3 * 0.1, "left": 0.2 * 0.3 * 0.1}
    x = (volume["left"] * -0.3) / sum(volume.values())          # centroid over the pier
    z = (volume["plank"] * 0.05 + volume["left"] * 0.15) / sum(volume.values())
    left = first["lookahead"][1]
    assert left["block"] == "left" and left["stable"]
    assert left["margin_g"] == pytest.approx((pier(design)[0] + x) / z, rel=1e-4)  # 0.0714 g
    assert first["first_failing_step"] == 1 and "below the minimum 0.1 g" in first["message"]
    assert kind == "plan_update" and update["feasible"] and update["repair"] == "hold"
    # the robot that set the plank down keeps it (or holds the left block) at step 1
    assert any(h["from_step"] <= 1 and (h["until_step"] < 0 or h["until_step"] > 1)
               for h in update["holds"]), update
    assert repaired["first_failing_step"] == -1
    assert all(s["margin_g"] >= 0.1 for s in repaired["lookahead"])
    assert_bag_replays(tmp_path / "bag")


def test_a_cell_plan_file_is_executed_its_robots_drawn_bad_poses_refused(make_node, tmp_path):
    """A design_file planned for a cell (the overhang stack, two robots) is executed as its
    timeline: s2 lands 10 mm out and turned 2 deg, the repair holds s2 while s3 is placed
    (its timeline on ~/plan_update), and with s3 measured ~/markers draws the robots as the
    HTML view does (the same gripper box at the holder's moved grip). Poses out of the
    plan's order, of a block not in the design, and a design that is not the plan's: a
    reason on ~/execution, the step reached kept, everything in the bag, which replays."""
    from rclpy.serialization import serialize_message

    from rbe_msgs.msg import AssemblyState
    from rbe_ros.cell import cell_from_dict
    from rbe_ros.io.execution import repair
    from rbe_ros.io.markers import gripper_box
    from rbe_ros.io.messages import state_to_dict

    from test_cell_execution import TWO_ROBOTS

    design = overhang_stack()
    path = tmp_path / "planned.json"
    cell_plan_file(design, TWO_ROBOTS, path)
    node = make_node(design_file=str(path), mcap_path=str(tmp_path / "bag"))
    states: list[tuple[str, dict]] = []
    drawn: list[dict] = []
    node._send_execution = (lambda send: lambda kind, m: (states.append((kind, m)),
                                                          send(kind, m)))(node._send_execution)
    node._encode_markers = (lambda encode: lambda m: (drawn.append(m), encode(m))[1])(
        node._encode_markers)
    node._repair = repair       # here, not in a worker process (spawning one takes seconds)

    def poses(sec: int, measured: dict, answers: int = 1) -> list[dict]:
        node._on_poses(serialize_message(dict_to_message(
            poses_to_dict(measured, "cell", sec * 1_000_000_000), BlockPoses)))
        return wait_until(lambda: [m for _, m in states if m["header"]["stamp"]["sec"] == sec]
                          if len([m for _, m in states if m["header"]["stamp"]["sec"] == sec])
                          >= answers else None, 60.0, f"the execution state of {sec}")

    at = {b.id: (b.position.tolist(), [0, 0, 0, 1]) for b in design.blocks}
    off = ((design.block("s2").position + [0.01, 0, 0]).tolist(),
           Rotation.from_euler("z", 2, degrees=True).as_quat().tolist())
    [first] = poses(1, {"s1": at["s1"]})
    assert first["active"] and first["current_step"] == 1 and first["first_failing_step"] == -1
    [wrong] = poses(2, {"s3": at["s3"]})                  # s2 comes first
    assert not wrong["active"] and wrong["current_step"] == 1 and wrong["message"] == (
        "measured blocks are not a prefix of the plan's order: 's3' (step 2) is measured but "
        "'s2' (step 1) is not")
    [ghost] = poses(3, {"ghost": at["s2"]})
    assert not ghost["active"] and ghost["current_step"] == 1 and "'ghost'" in ghost["message"]
    # the as-built state kept s3 as measured: the design again forgets the poses
    sent = len(states)
    state, name = node.design_message(str(path))
    node._send_design(state, node.design_cell(str(path)), name=name)
    wait_until(lambda: len(states) > sent, 30.0, "the design's state")
    assert states[-1][1]["active"] and states[-1][1]["current_step"] == 0, states[-1][1]["message"]
    poses(31, {"s1": at["s1"]})
    failing, update, repaired = poses(4, {"s2": off}, answers=3)
    assert failing["current_step"] == 2 and failing["first_failing_step"] == 2
    assert update["repair"] == "hold" and update["feasible"] and update["timeline"]
    assert repaired["first_failing_step"] == -1
    drawn.clear()
    [built] = poses(5, {"s3": at["s3"]})
    assert built["active"] and built["current_step"] == 3
    wait_until(lambda: any(m["ns"] == "grippers" for a in drawn for m in a["markers"]), 30.0,
               "the robots' markers")
    robots = next(a["markers"] for a in drawn
                  if any(m["ns"] == "grippers" for m in a["markers"]))
    assert sum(m["ns"] == "robots" for m in robots) == 2
    # with the blocks of the last report, after its DELETEALL: one array draws both
    assert robots[0]["action"] == 3 and any(m["ns"] == "blocks" for m in robots)
    # s2's holder: its gripper box where the HTML view draws it from the repaired timeline
    holder = next(a for a in update["timeline"] if a["action"] == "hold" and a["block"] == "s2")
    centre, quat = gripper_box(holder, cell_from_dict(TWO_ROBOTS).robot(holder["robot"]))
    [box] = [m for m in robots if m["ns"] == "grippers"]
    assert [box["pose"]["position"][k] for k in "xyz"] == pytest.approx(centre)
    assert [box["pose"]["orientation"][k] for k in "xyzw"] == pytest.approx(quat)
    other = make_scene("other", [design.block("ground"), design.block("s1")])
    node._on_design(serialize_message(dict_to_message(state_to_dict(other, "cell", 6 * 10**9),
                                                      AssemblyState)))
    [mismatch] = wait_until(lambda: [m for _, m in states if m["header"]["stamp"]["sec"] == 6],
                            30.0, "6")
    assert not mismatch["active"] and "does not match the design" in mismatch["message"]
    node.destroy_node()
    topics = [m.topic.rsplit("/", 1)[1] for m in read_bag(tmp_path / "bag")]
    assert topics.count("poses") == 6 and topics.count("design") == 3
    assert topics.count("execution") + topics.count("plan_update") >= len(states)
    result = assert_bag_replays(tmp_path / "bag")
    assert result.executed == topics.count("execution") + topics.count("plan_update")


def test_a_cell_plan_of_the_node_is_executed_for_its_cell(make_node, tmp_path):
    """A ~/plan result for a cell is executed for that cell: the cell recorded with the
    settings before the plan's design, so that the replay repairs as the node did (a hold
    at the robot's grip, the repaired timeline)."""
    from rclpy.serialization import serialize_message

    from rbe_msgs.msg import AssemblyState
    from rbe_ros.analysis.planning import plan_sequence
    from rbe_ros.cell import cell_from_dict
    from rbe_ros.io.execution import repair
    from rbe_ros.io.messages import scene_from_state_dict, state_to_dict
    from rbe_ros.io.replay import settings_cell

    from test_cell_execution import TWO_ROBOTS

    cell = cell_from_dict(TWO_ROBOTS)
    design = scene_from_state_dict(state_to_dict(replace(overhang_stack(), sequence=())))
    plan = plan_sequence(design, 1, cell=cell)
    assert plan.feasible and plan.order == ["s1", "s2", "s3", "c"]
    node = make_node(mcap_path=str(tmp_path / "bag"))
    node._repair = repair       # here, not in a worker process (spawning one takes seconds)
    states: list[dict] = []
    node._send_execution = (lambda send: lambda kind, m: (states.append(m), send(kind, m)))(
        node._send_execution)
    node._on_design(serialize_message(dict_to_message(state_to_dict(design, "cell", 10**9),
                                                      AssemblyState)))
    node._adopt(plan, {"frame_id": "cell", "stamp": {"sec": 0, "nanosec": 0}})
    wait_until(lambda: node._execution.cell == cell and states and states[-1]["active"],
               30.0, "the plan's execution state")
    at = {b.id: (b.position.tolist(), [0, 0, 0, 1]) for b in design.blocks}
    off = ((design.block("s2").position + [0.01, 0, 0]).tolist(), [0, 0, 0, 1])
    node._on_poses(serialize_message(dict_to_message(poses_to_dict(
        {"s1": at["s1"], "s2": off}, "cell", 10 * 10**9), BlockPoses)))
    update = wait_until(lambda: next((m for m in states if "repair" in m), None), 60.0,
                        "the plan update")
    assert update["repair"] == "hold" and update["timeline"]
    assert update["holds"][0]["has_grip"]
    node.destroy_node()
    settings = [json.loads(m.data["data"]) for m in read_bag(tmp_path / "bag")
                if m.topic.endswith("/settings")]
    assert settings_cell(settings[-1]) == cell and settings_cell(settings[0]) is None
    result = assert_bag_replays(tmp_path / "bag")
    assert result.executed == len(states)
    # a repaired timeline the replay does not make again is a difference
    run = next(r for r in result.runs if any(k == "plan_update" for k, _ in r.execution))
    other = [(k, {**m, "timeline": [{**a, "robot": "r9"} for a in m["timeline"]]}
              if k == "plan_update" else m) for k, m in run.execution]
    found = compare_execution(0, run, other)
    assert [(d.where, d.field) for d in found] == [("plan_update", "timeline")]


def _reports(node) -> list:
    """The reports ``node`` publishes from now on (its _publish wrapped)."""
    out: list = []
    publish = node._publish

    def keep(scene, report, header, state=None):
        out.append(report)
        return publish(scene, report, header, state)

    node._publish = keep
    return out


@pytest.mark.long      # ~4 s here (its core: tests/test_execution_report.py, 1 s)
def test_the_report_of_a_held_step_applies_the_plans_holds(make_node, tmp_path):
    """While the plan holds blocks, ~/report checks the measured blocks with the holds the
    plan has at that step (as ~/execution's as_built does), and says so; not the measured
    blocks alone (which need tension there)."""
    from rbe_ros import generators as gen
    from rbe_ros.analysis.pipeline import check_sequence
    from rbe_ros.analysis.planning import plan_sequence

    plan = plan_sequence(gen.semicircular_arch(7), max_held=2).scene
    steps = check_sequence(plan)
    k = next(i for i, r in enumerate(steps) if r.held_blocks)
    path = tmp_path / "planned.json"
    path.write_text(json.dumps(scene_to_dict(plan)))
    node = make_node(design_file=str(path), mcap_path=str(tmp_path / "bag"), lookahead_steps=1)
    reports = _reports(node)
    states: list[dict] = []
    node._send_execution = (lambda send: lambda kind, m: (states.append(m), send(kind, m)))(
        node._send_execution)
    at = {b.id: (b.position.tolist(), b.orientation.tolist()) for b in plan.blocks}
    for sec, block in enumerate(plan.sequence[:k + 1], 1):
        node._on_poses(serialize_message(dict_to_message(
            poses_to_dict({block: at[block]}, "cell", sec * 1_000_000_000), BlockPoses)))
        wait_until(lambda: any(m["header"]["stamp"]["sec"] == sec for m in states), 30.0,
                   f"the execution state of {sec}")
    node.destroy_node()
    report = reports[-1]
    assert report.stable and report.held_blocks == steps[k].held_blocks
    assert report.message.endswith(f"as the plan has it at step {k}: held "
                                   f"{', '.join(steps[k].held_blocks)}")
    assert states[-1]["as_built"]["status"] == 0
    assert states[-1]["as_built"]["held_blocks"] == list(steps[k].held_blocks)
    assert_bag_replays(tmp_path / "bag")


def test_an_unreadable_design_file_is_named_on_the_report_and_the_node_goes_on(make_node,
                                                                              tmp_path):
    """A design_file that cannot be read: one ERROR line at start naming the path and why,
    ~/report INVALID_INPUT saying the same (not "the scene has no blocks"), and so do poses
    after it; a design sent on ~/design is then checked."""
    from rbe_msgs.msg import AssemblyState
    from rbe_ros import generators as gen
    from rbe_ros.io.messages import state_to_dict

    path = tmp_path / "missing.json"
    node = make_node(design_file=str(path))
    reports = _reports(node)        # (the design's report may be out already: wait for one)
    node._on_poses(serialize_message(dict_to_message(
        poses_to_dict({"b00": ([0, 0, 0.5], [0, 0, 0, 1])}, "cell", 10**9), BlockPoses)))
    wait_until(lambda: reports, 30.0, "the report of the poses")
    why = f"design_file {str(path)!r} could not be read: cannot read scene {str(path)!r}: " \
        "No such file or directory (send a design on ~/design)"
    assert reports[0].status == Status.INVALID_INPUT and why in reports[0].message
    design = gen.stack(2)
    node._on_design(serialize_message(dict_to_message(state_to_dict(design, "cell", 2 * 10**9),
                                                      AssemblyState)))
    wait_until(lambda: reports[-1].status == Status.STABLE, 30.0, "the design's report")
    assert all(why in r.message for r in reports[:-1])


def test_a_design_file_scene_keeps_its_name_in_reports_and_their_replay(make_node, tmp_path):
    """A message has no name field, so a design came out named after its frame ("world");
    the node knows the design file's scene name: the reports and the log name the design
    by it, the settings record it, and the replay names it so too (messages compared)."""
    from rbe_ros import generators as gen
    from rbe_ros.io.replay import Tolerances

    design = gen.stack(2)
    path = tmp_path / "design.json"
    path.write_text(json.dumps(scene_to_dict(design)))
    node = make_node(design_file=str(path), mcap_path=str(tmp_path / "bag"))
    reports = _reports(node)
    node._on_poses(serialize_message(dict_to_message(
        poses_to_dict({"b7": ([0, 0, 0.5], [0, 0, 0, 1])}, "cell", 10**9), BlockPoses)))
    wait_until(lambda: any("'b7'" in r.message for r in reports), 30.0, "the report")
    node.destroy_node()
    [unknown] = [r for r in reports if "'b7'" in r.message]
    assert f"not in the design {design.name!r}: 'b7'" in unknown.message, unknown.message
    assert design.name != "world"
    assert_bag_replays(tmp_path / "bag", tolerances=Tolerances(message=1e-9))
