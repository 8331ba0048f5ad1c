"""rbe_lifecycle_node over DDS: every transition, with ~/check and ~/check_sequence present
only while active (~/assembly subscribed from the first activate to cleanup, so that what
arrives in a pause is counted), the bag open from configure to cleanup; the measured poses
kept across deactivate/activate; a bad design_file or mcap_path fails configure with one
error line."""
from __future__ import annotations

import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rbe_msgs.msg import AssemblyState, BlockPoses, StabilityReport

from rbe_ros import generators as gen
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.io.messages import poses_to_dict, state_to_dict
from rbe_ros.io.poses import scene_at_poses
from rbe_ros.io.replay import read_runs
from rbe_ros.ros.convert import dict_to_message
from rbe_ros.ros.live import NodeProcess

from rbe_client import DENSITY, G, NODE, Client, stacked_boxes, state_msg, wait_future, \
    wait_until
from test_poses_node import Pipeline

MODULE = "rbe_ros.ros.lifecycle_node"


class Lifecycle:
    def __init__(self, client: Client):
        self.client = client
        self.get = client.node.create_client(GetState, f"{NODE}/get_state")
        self.change = client.node.create_client(ChangeState, f"{NODE}/change_state")

    def state(self) -> int:
        assert self.get.wait_for_service(timeout_sec=30.0)
        return wait_future(self.get.call_async(GetState.Request())).current_state.id

    def transition(self, transition: int) -> bool:
        assert self.change.wait_for_service(timeout_sec=30.0)
        request = ChangeState.Request(transition=Transition(id=transition))
        return wait_future(self.change.call_async(request)).success


def interfaces(client: Client) -> tuple[bool, bool, bool]:
    """Whether ~/assembly is subscribed, ~/check served and ~/check_sequence served."""
    return (client.state_pub.get_subscription_count() >= 1, client.check.service_is_ready(),
            client.action.server_is_ready())


def test_every_transition_with_the_interfaces_only_while_active(rclpy_context, tmp_path):
    bag = tmp_path / "bag"
    proc = NodeProcess(["-p", f"mcap_path:={bag}"], tmp_path / "node.log", MODULE)
    client = Client(rclpy_context, markers=False)
    life = Lifecycle(client)
    try:
        assert life.state() == State.PRIMARY_STATE_UNCONFIGURED
        assert interfaces(client) == (False, False, False) and not bag.exists()
        assert life.transition(Transition.TRANSITION_CONFIGURE)
        assert life.state() == State.PRIMARY_STATE_INACTIVE
        assert bag.is_dir()
        assert interfaces(client) == (False, False, False)
        assert life.transition(Transition.TRANSITION_ACTIVATE)
        assert life.state() == State.PRIMARY_STATE_ACTIVE
        wait_until(lambda: interfaces(client) == (True, True, True), what="the interfaces")
        # box b (1 m cube) a quarter off box a: stands; ground carries both, 2 * 2000 kg * g
        report = client.call_check(state_msg(stacked_boxes(0.25)))
        assert report.status == StabilityReport.STABLE
        [ground] = [i for i in report.interfaces if "ground" in (i.block_a, i.block_b)]
        assert abs(ground.normal_resultant - 2 * DENSITY * G) < 1e-6 * DENSITY * G
        assert client.call_check(state_msg(stacked_boxes(0.75))).status == \
            StabilityReport.TENSION_REQUIRED                 # b's centre beyond a's edge
        assert life.transition(Transition.TRANSITION_DEACTIVATE)
        assert life.state() == State.PRIMARY_STATE_INACTIVE
        # ~/assembly stays subscribed: what comes in the pause is counted, not lost unseen
        wait_until(lambda: interfaces(client) == (True, False, False), what="no services")
        assert life.transition(Transition.TRANSITION_ACTIVATE)       # and back
        wait_until(lambda: interfaces(client) == (True, True, True), what="the interfaces")
        assert life.transition(Transition.TRANSITION_DEACTIVATE)
        assert life.transition(Transition.TRANSITION_CLEANUP)
        assert life.state() == State.PRIMARY_STATE_UNCONFIGURED
        runs = read_runs(bag)                                        # closed: readable
        assert [r.reports[0]["status"] for r in runs] == [
            StabilityReport.STABLE, StabilityReport.TENSION_REQUIRED]
        assert life.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
        assert life.state() == State.PRIMARY_STATE_FINALIZED
    finally:
        client.close()
        assert proc.stop() == 0
    assert "Traceback" not in proc.output(), proc.output()


def test_a_bad_design_file_or_mcap_path_fails_configure_with_one_line(rclpy_context,
                                                                     tmp_path):
    (tmp_path / "file").write_text("")
    cases = {"design_file": tmp_path / "missing.json",
             "mcap_path": tmp_path / "file" / "bag"}              # under a plain file
    for name, path in cases.items():
        proc = NodeProcess(["-p", f"{name}:={path}"], tmp_path / f"{name}.log", MODULE)
        client = Client(rclpy_context, markers=False)
        life = Lifecycle(client)
        try:
            assert not life.transition(Transition.TRANSITION_CONFIGURE)
            assert life.state() == State.PRIMARY_STATE_UNCONFIGURED
        finally:
            client.close()
            assert proc.stop() == 0
        out = proc.output()
        errors = [line for line in out.splitlines() if "configure failed" in line]
        assert len(errors) == 1 and str(path) in errors[0], out
        assert "Traceback" not in out, out


def test_measured_poses_survive_deactivate_activate_and_the_pause_is_counted(rclpy_context,
                                                                             tmp_path):
    design = gen.running_bond_wall(3, 3)                 # 10 bricks on a footing
    order = list(design.sequence)
    proc = NodeProcess([], tmp_path / "node.log", MODULE)
    client = Client(rclpy_context, markers=False)
    life = Lifecycle(client)
    pipeline = Pipeline(rclpy_context)
    levels: list[tuple[int, str]] = []
    lock = threading.Lock()

    def keep(msg):
        with lock:
            levels.extend((s.level, s.message, {kv.key: kv.value for kv in s.values})
                          for s in msg.status if s.name.endswith(NODE))

    client.node.create_subscription(DiagnosticArray, "/diagnostics", keep, 10)

    def send(stamp: int, bids) -> None:
        poses = {b: (design.block(b).position.tolist(), design.block(b).orientation.tolist())
                 for b in bids}
        pipeline.poses.publish(dict_to_message(poses_to_dict(poses, "wall", stamp * 10**9),
                                               BlockPoses))

    def seen(level: int, text: str, dropped: int | None = None) -> bool:
        with lock:
            levels.clear()

        def matches(lv, m, values):
            return lv == level and text in m and \
                (dropped is None or values["dropped states"] == str(dropped))
        return wait_until(lambda: any(matches(*x) for x in list(levels)), 60.0,
                          f"/diagnostics {text} {dropped}")
    try:
        assert life.transition(Transition.TRANSITION_CONFIGURE)
        assert seen(DiagnosticStatus.STALE, "inactive")        # configured, not checking
        assert life.transition(Transition.TRANSITION_ACTIVATE)
        wait_until(pipeline.ready, 60.0, "the node's topics")
        pipeline.design.publish(dict_to_message(state_to_dict(design, "wall", 10**9 * 100),
                                                AssemblyState))
        wait_until(lambda: pipeline.report(100), 60.0, "the design's report")
        built = order[:-3]                              # the last course waits
        for k, bid in enumerate(built):                 # one at a time: none superseded
            send(101 + k, [bid])
            wait_until(lambda: pipeline.report(101 + k), 60.0, f"the report of {bid}")
        before = pipeline.report(100 + len(built))
        assert before.status == StabilityReport.STABLE and before.num_blocks == 1 + len(built)
        assert life.transition(Transition.TRANSITION_DEACTIVATE)
        assert seen(DiagnosticStatus.STALE, "inactive")
        # an incremental camera goes on in the pause: the last course's bricks, one a
        # message, then the first brick again twice; merged, not checked
        for k, bids in enumerate([[b] for b in order[-3:]] + [order[:1]] * 2):
            send(200 + k, bids)
        # each superseded as it comes (the dropped count of /diagnostics), the newest waits
        assert seen(DiagnosticStatus.STALE, "inactive", before.dropped_states + 4)
        assert not pipeline.report(204)
        assert life.transition(Transition.TRANSITION_ACTIVATE)
        # the newest first, with every brick measured in the pause: the whole wall stands
        paused = wait_until(lambda: pipeline.report(204), 60.0, "the newest after activate")
        assert seen(DiagnosticStatus.OK, "ok")
        send(300, order[-1:])                           # the last brick measured again
        after = wait_until(lambda: pipeline.report(300), 60.0, "the report after activate")
    finally:
        pipeline.close()
        client.close()
        assert proc.stop() == 0
    out = proc.output()
    assert "Traceback" not in out, out
    # every brick still measured: the wall stands on the footing, as the core computes it
    assert after.status == StabilityReport.STABLE and after.num_blocks == 1 + len(order)
    assert paused.status == StabilityReport.STABLE and paused.num_blocks == 1 + len(order)
    assert [r.header.stamp.sec for r in pipeline.reports if r.header.stamp.sec >= 200] == \
        [204, 300]                                      # nothing that waited, newest first
    assert [r.header.stamp.sec for r in pipeline.reports].count(100) == 1   # design once
    final = check_scene(scene_at_poses(design, {b: (design.block(b).position,
                                                    design.block(b).orientation)
                                                for b in order}))
    assert [(i.block_a, i.block_b) for i in after.interfaces] == \
        [(i.block_a, i.block_b) for i in final.interfaces]
    assert after.dropped_states - before.dropped_states == 4
    assert "5 messages" in out and "arrived while inactive" in out, out
    assert "deactivated" in out and "activated" in out
