"""Test-side helpers: a client node that talks to ``rbe_node`` (started as a process by
:class:`rbe_ros.ros.live.NodeProcess`), and small scenes and states."""
from __future__ import annotations

import json
import threading
import time
from contextlib import contextmanager

from rbe_msgs.action import CheckSequence, PlanSequence
from rbe_msgs.msg import AssemblyState, StabilityReport
from rbe_msgs.srv import CheckAssembly
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from rbe_ros.io.messages import state_to_dict
from rbe_ros.ros.convert import dict_to_message, message_to_dict
from rbe_ros.ros.live import NodeProcess
from rbe_ros.scene import box_block, make_scene

NODE = "/rbe_node"
TIMEOUT = 15.0

DENSITY, G = 2000.0, 9.81


def stacked_boxes(shift: float):
    """A support slab, box a on it and box b on a, shifted by ``shift`` of its 1 m width."""
    return make_scene("stack", [
        box_block("ground", (3, 3, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (0, 0, 0.5), density=DENSITY),
        box_block("b", (1, 1, 1), (shift, 0, 1.5), density=DENSITY),
    ])


def tower(n: int):
    """A straight stack of ``n`` boxes on a slab (every step stable)."""
    return make_scene("tower", [box_block("ground", (2, 2, 0.2), (0, 0, -0.1), support=True,
                                          density=DENSITY)]
                      + [box_block(f"b{i:02d}", (0.5, 0.5, 0.2), (0, 0, 0.1 + 0.2 * i),
                                   density=DENSITY) for i in range(n)])


_stamps = iter(range(1000, 10**6))


def state_msg(scene, frame_id: str = "") -> AssemblyState:
    """An AssemblyState of ``scene`` with a stamp unique in this test run."""
    return dict_to_message(state_to_dict(scene, frame_id, next(_stamps) * 1_000_000_000 + 17),
                           AssemblyState)


def stamp_of(msg) -> tuple[int, int]:
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def canonical(msg_or_dict) -> str:
    """A string equal for field-equal messages (exact floats; NaN equal to NaN)."""
    d = msg_or_dict if isinstance(msg_or_dict, dict) else message_to_dict(msg_or_dict)
    return json.dumps(d, sort_keys=True, allow_nan=True)


def wait_until(predicate, timeout: float = TIMEOUT, what: str = "condition"):
    end = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)


def wait_future(future, timeout: float = TIMEOUT, what: str = "future"):
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if not (future.done() or done.wait(timeout)):
        raise AssertionError(f"timed out after {timeout} s waiting for {what}")
    return future.result()


class Client:
    """A node in the test process with everything needed to talk to ``rbe_node``; spun by
    its own executor thread. Keeps every report and marker array it receives and every state
    it sends, for the comparison with the node's bag."""

    def __init__(self, context, markers: bool = True):
        """``markers``: subscribe to ~/markers too (the arrays of a large scene are slow to
        take in, and a reliable reader that lags holds the node back)."""
        self.node = Node("rbe_test_client", context=context)
        self.lock = threading.Condition()
        self.reports: list[StabilityReport] = []      # from ~/report
        self.markers: list[MarkerArray] = []
        self.sent_states: list[AssemblyState] = []    # by topic, service and action
        self.other_reports: list[StabilityReport] = []  # service responses, action results
        reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.VOLATILE)
        self.state_pub = self.node.create_publisher(AssemblyState, f"{NODE}/assembly", reliable)
        self.node.create_subscription(StabilityReport, f"{NODE}/report",
                                      self._keep(self.reports), reliable)
        if markers:
            self.node.create_subscription(MarkerArray, f"{NODE}/markers",
                                          self._keep(self.markers), reliable)
        self.check = self.node.create_client(CheckAssembly, f"{NODE}/check")
        self.action = ActionClient(self.node, CheckSequence, f"{NODE}/check_sequence")
        self.plan = ActionClient(self.node, PlanSequence, f"{NODE}/plan")
        # One executor thread, and every ActionClient request is made from it (see
        # _in_executor): rclpy's ActionClient registers a request's sequence number only
        # after sending it, without a lock, so a response handled by another thread in
        # between is dropped ("Ignoring unexpected goal response").
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _keep(self, store: list):
        def callback(msg):
            with self.lock:
                store.append(msg)
                self.lock.notify_all()
        return callback

    def wait_ready(self, proc: NodeProcess, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout

        def left():
            if proc.proc.poll() is not None:
                raise AssertionError(f"rbe_node exited ({proc.proc.returncode}):\n"
                                     f"{proc.output()}")
            return max(end - time.monotonic(), 0.1)

        wait_until(lambda: left() and self.check.wait_for_service(timeout_sec=0.2),
                   left(), "the ~/check service")
        wait_until(lambda: left() and self.action.wait_for_server(timeout_sec=0.2),
                   left(), "the ~/check_sequence action server")
        wait_until(lambda: left() and self.plan.wait_for_server(timeout_sec=0.2),
                   left(), "the ~/plan action server")
        wait_until(lambda: left() and self.state_pub.get_subscription_count() >= 1
                   and self.node.count_publishers(f"{NODE}/report") >= 1
                   and self.node.count_publishers(f"{NODE}/markers") >= 1,
                   left(), "the ~/assembly subscription and ~/report, ~/markers publishers")

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(5.0)
        self.action.destroy()
        self.plan.destroy()
        self.node.destroy_node()

    def _in_executor(self, fn, *args, timeout: float = TIMEOUT):
        """``fn(*args)`` run by the executor thread; its return value."""
        return wait_future(self.executor.create_task(fn, *args), timeout, fn.__name__)

    # --- topic ------------------------------------------------------------------------------

    def publish(self, state: AssemblyState) -> None:
        self.sent_states.append(state)
        self.state_pub.publish(state)

    def _wait_for(self, store: list, predicate, timeout: float, what: str):
        end = time.monotonic() + timeout
        with self.lock:
            while True:
                found = [m for m in store if predicate(m)]
                if found:
                    return found
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}")
                self.lock.wait(left)

    def report_for(self, state: AssemblyState, timeout: float = TIMEOUT,
                   step: int = -1) -> StabilityReport:
        """The report on ~/report for ``state`` (matched by header stamp) and ``step``."""
        key = stamp_of(state)
        return self._wait_for(self.reports, lambda r: stamp_of(r) == key and r.step_index == step,
                              timeout, f"the report of stamp {key} step {step}")[0]

    def markers_for(self, report: StabilityReport, timeout: float = TIMEOUT) -> MarkerArray:
        """The marker array published with ``report`` (same stamp; the last one)."""
        key = stamp_of(report)
        return self._wait_for(self.markers,
                              lambda m: m.markers and stamp_of(m.markers[0]) == key,
                              timeout, f"markers of stamp {key}")[-1]

    # --- service and action -----------------------------------------------------------------

    def call_check(self, state: AssemblyState, timeout: float = TIMEOUT) -> StabilityReport:
        self.sent_states.append(state)
        response = wait_future(self.check.call_async(CheckAssembly.Request(assembly=state)),
                               timeout, "the ~/check response")
        self.other_reports.append(response.report)
        return response.report

    def send_goal(self, state: AssemblyState, feedback: list, on_feedback=None,
                  timeout: float = TIMEOUT):
        """Send a CheckSequence goal; feedback messages are appended to ``feedback``.
        Returns the accepted goal handle."""
        self.sent_states.append(state)
        return self._send(self.action, CheckSequence.Goal(assembly=state), feedback,
                          on_feedback, timeout)

    def send_plan(self, goal: PlanSequence.Goal, feedback: list, on_feedback=None,
                  timeout: float = TIMEOUT):
        """Send a PlanSequence goal to ~/plan (as :meth:`send_goal`)."""
        return self._send(self.plan, goal, feedback, on_feedback, timeout)

    def _send(self, action: ActionClient, goal, feedback: list, on_feedback, timeout: float):
        def callback(msg):
            with self.lock:
                feedback.append(msg.feedback)
                self.lock.notify_all()
            if on_feedback is not None:
                on_feedback(msg.feedback)

        future = self._in_executor(lambda: action.send_goal_async(
            goal, feedback_callback=callback))
        handle = wait_future(future, timeout, "the goal response")
        assert handle.accepted
        return handle

    def cancel(self, handle, timeout: float = TIMEOUT):
        """The CancelGoal response for an accepted goal."""
        return wait_future(self._in_executor(handle.cancel_goal_async), timeout,
                           "the cancel response")

    def result(self, handle, timeout: float = TIMEOUT):
        """(status, result) of an accepted goal."""
        response = wait_future(self._in_executor(handle.get_result_async), timeout,
                               "the action result")
        self.other_reports.extend(response.result.reports)
        return response.status, response.result


@contextmanager
def node_and_client(context, ros_args: list[str], log, markers: bool = False):
    """An rbe_node process started with ``ros_args`` (its output in ``log``) and a
    :class:`Client` it answers; both closed on exit."""
    proc = NodeProcess(ros_args, log)
    client = Client(context, markers=markers)
    try:
        client.wait_ready(proc)
        yield proc, client
    finally:
        client.close()
        proc.stop()


__all__ = ["Client", "NodeProcess", "canonical", "node_and_client", "stacked_boxes", "state_msg",
           "tower", "wait_future", "wait_until"]
