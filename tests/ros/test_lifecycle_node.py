"""rbe_lifecycle_node over DDS: every transition, with ~/assembly, ~/check and
~/check_sequence present only while active, the bag open from configure to cleanup; a bad
design_file or mcap_path fails configure with one error line."""
from __future__ import annotations

from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rbe_msgs.msg import StabilityReport

from rbe_ros.io.replay import read_runs
from rbe_ros.ros.live import NodeProcess

from rbe_client import DENSITY, G, NODE, Client, stacked_boxes, state_msg, wait_future, \
    wait_until

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
        wait_until(lambda: interfaces(client) == (False, False, False), what="no interfaces")
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
