"""Live replay: play recorded states into a running ``rbe_node`` and collect its reports.

:func:`live_recheck` is what :func:`rbe_ros.io.replay.replay_bag` takes as ``recheck``. The
node is started here (``python -m rbe_ros.ros.node`` under a unique node name, with the
parameters of the bag's check options, in the ROS_DOMAIN_ID of the environment) or, with
``node_name``, the running node of that name is used, its parameters set to the bag's
settings as below and put back as they were at the end.

States are sent one at a time, each after the previous one is answered (the node checks the
newest state on its topic and drops a waiting one under load): a state with a sequence as a
``~/check_sequence`` goal (the result holds one report per step), a state without on the
``~/assembly`` topic, answered by the report on ``~/report`` with its header stamp; a design
on ``~/design`` and measured poses on ``~/poses`` likewise (the node merges each into its
as-built state; one it dropped unchecked when recorded is answered now, and the answer left
out); a ~/plan goal as a goal of ``~/plan`` without its time limit (the result is its
answer; a plan recorded as stopped cannot be stopped at the same block live: ValueError,
replay it offline). Before a state whose recorded settings (``~/settings``: check options
and frame_id) differ from those last set, the node's parameters are set to them through its
parameter service, so a bag with run-time parameter changes replays with the settings of
each state.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import rclpy
from rbe_msgs.action import CheckSequence, PlanSequence
from rbe_msgs.msg import AssemblyState, BlockPoses, StabilityReport
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from ..analysis.option_spec import node_parameters
from ..analysis.options import CheckOptions
from ..io.replay import DESIGN, PLAN, POSES, STATE, Run, run_settings, stopped_at
from .convert import dict_to_message, message_to_dict


def _ros_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.17e}"
    return str(value)


class NodeProcess:
    """``python -m module --ros-args *ros_args`` as a process (default: rbe_node), its output
    in ``log`` (a temporary file, removed at :meth:`stop`, if not given)."""

    def __init__(self, ros_args: list[str], log: Path | None = None,
                 module: str = "rbe_ros.ros.node"):
        self._temporary = log is None
        self.log = Path(tempfile.mkstemp(prefix="rbe_node_", suffix=".log")[1]) if log is None \
            else Path(log)
        self._out = self.log.open("wb")
        self.proc = subprocess.Popen([sys.executable, "-m", module, "--ros-args",
                                      *ros_args], stdout=self._out, stderr=subprocess.STDOUT,
                                     env=dict(os.environ))

    @classmethod
    def named(cls, name: str, parameters: dict[str, object]) -> "NodeProcess":
        """The node named ``name`` with ``parameters`` (a temporary log)."""
        args = ["-r", f"__node:={name}"]
        for key, value in parameters.items():
            args += ["-p", f"{key}:={_ros_value(value)}"]
        return cls(args)

    def output(self) -> str:
        if not self._out.closed:
            self._out.flush()
        return self.log.read_text(errors="replace")

    def stop(self, timeout: float = 15.0) -> int:
        """SIGINT (as Ctrl-C), then the exit status. A node still running after ``timeout``
        is killed, and RuntimeError says so with its output."""
        hung = ""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                hung = self.output()
        self._out.close()
        if self._temporary:
            self.log.unlink(missing_ok=True)
        if hung:
            raise RuntimeError(f"rbe_node did not stop on SIGINT within {timeout:g} s:\n{hung}")
        return self.proc.returncode


class _Client:
    def __init__(self, context, node_name: str):
        base = "/" + node_name.strip("/")
        self.node = Node(f"rbe_replay_client_{os.getpid()}", context=context)
        self.lock = threading.Condition()
        self.reports: list[StabilityReport] = []
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        self.publisher = self.node.create_publisher(AssemblyState, f"{base}/assembly", qos)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.publishers = {
            STATE: (self.publisher, AssemblyState),
            DESIGN: (self.node.create_publisher(AssemblyState, f"{base}/design", latched),
                     AssemblyState),
            POSES: (self.node.create_publisher(BlockPoses, f"{base}/poses", qos), BlockPoses)}
        self.node.create_subscription(StabilityReport, f"{base}/report", self._on_report, qos)
        self.action = ActionClient(self.node, CheckSequence, f"{base}/check_sequence")
        self.plan_action = ActionClient(self.node, PlanSequence, f"{base}/plan")
        self.parameters = AsyncParameterClient(self.node, base)
        self.base = base
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_report(self, msg) -> None:
        with self.lock:
            self.reports.append(msg)
            self.lock.notify_all()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(5.0)
        self.action.destroy()
        self.plan_action.destroy()
        self.node.destroy_node()

    def _wait(self, future, timeout: float, what: str):
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not (future.done() or done.wait(timeout)):
            raise TimeoutError(f"no {what} from {self.base} within {timeout:g} s")
        return future.result()

    def _in_executor(self, fn, timeout: float, what: str):
        # rclpy's ActionClient registers a request after sending it, without a lock: every
        # request is made from the executor thread so no response can overtake it.
        return self._wait(self.executor.create_task(fn), timeout, what)

    def wait_ready(self, timeout: float, alive: Callable[[], None]) -> None:
        end = time.monotonic() + timeout
        while True:
            alive()
            if (self.action.server_is_ready() and self.plan_action.server_is_ready()
                    and all(p.get_subscription_count() >= 1 for p, _ in self.publishers.values())
                    and self.node.count_publishers(f"{self.base}/report") >= 1):
                return
            if time.monotonic() > end:
                raise TimeoutError(f"{self.base} is not up after {timeout:g} s (is it running, "
                                   "in this ROS_DOMAIN_ID?)")
            time.sleep(0.05)

    def _parameter_call(self, call, what: str, timeout: float):
        """The response of ``call()`` on the node's parameter services (named ``what``)."""
        if not self.parameters.wait_for_services(timeout):
            raise TimeoutError(f"no parameter service of {self.base} within {timeout:g} s")
        return self._wait(self._in_executor(call, timeout, what), timeout, f"{what} response")

    def set_parameters(self, values: dict[str, object], timeout: float) -> None:
        """Set the node's parameters to ``values`` (RuntimeError naming those it refused)."""
        params = [Parameter(k, value=v) for k, v in values.items()]
        response = self._parameter_call(lambda: self.parameters.set_parameters(params),
                                        "set_parameters", timeout)
        refused = [f"{p.name}: {r.reason}" for p, r in zip(params, response.results)
                   if not r.successful]
        if refused:
            raise RuntimeError(f"{self.base} refused the recorded settings: {'; '.join(refused)}")

    def get_parameters(self, names: list[str], timeout: float) -> dict[str, object]:
        """The node's values of the parameters ``names``."""
        response = self._parameter_call(lambda: self.parameters.get_parameters(names),
                                        "get_parameters", timeout)
        return {n: parameter_value_to_python(v) for n, v in zip(names, response.values)}

    def _result(self, action: ActionClient, goal, timeout: float, what: str):
        """The result of ``goal`` sent to ``action`` (named ``what``)."""
        future = self._in_executor(lambda: action.send_goal_async(goal), timeout,
                                   "goal response")
        handle = self._wait(future, timeout, "goal response")
        if not handle.accepted:
            raise RuntimeError(f"{self.base} rejected the {what} goal")
        return self._wait(self._in_executor(handle.get_result_async, timeout, "result"),
                          timeout, f"{what} result").result

    def check_sequence(self, state, timeout: float) -> list[dict]:
        result = self._result(self.action, CheckSequence.Goal(assembly=state), timeout,
                              "check_sequence")
        return [message_to_dict(r) for r in result.reports]

    def plan(self, goal, timeout: float) -> list[dict]:
        """The result dict of a ~/plan goal (its one answer)."""
        return [message_to_dict(self._result(self.plan_action, goal, timeout, "plan"))]

    def check_whole(self, state, timeout: float, kind: str = STATE) -> list[dict]:
        """Publish ``state`` (a message of ``kind``) and wait for the report with its stamp."""
        key = (state.header.stamp.sec, state.header.stamp.nanosec)
        with self.lock:
            self.reports.clear()
        self.publishers[kind][0].publish(state)
        end = time.monotonic() + timeout
        with self.lock:
            while True:
                for r in self.reports:
                    if (r.header.stamp.sec, r.header.stamp.nanosec) == key and r.step_index == -1:
                        return [message_to_dict(r)]
                left = end - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no report for the state of stamp {key} on "
                                       f"{self.base}/report within {timeout:g} s")
                self.lock.wait(left)


def live_goal(run: Run) -> PlanSequence.Goal:
    """The recorded ~/plan goal of ``run`` to send again, without its time limit (how long a
    plan ran is not part of its result). A plan that was stopped cannot be stopped at the
    same block over DDS: ValueError, replay it offline."""
    if stopped_at(run) is not None:
        raise ValueError(f"{run.describe()}: the recorded plan was stopped; replay --live "
                         "cannot stop a plan after as many blocks: replay the bag offline")
    return dict_to_message({**run.state, "time_limit": 0.0}, PlanSequence.Goal)


def settings_parameters(run: Run, options: CheckOptions) -> dict[str, object]:
    """rbe_node parameters of the settings ``run`` was checked with (from the option table)."""
    run_options, frame_id = run_settings(run, options)
    return {**node_parameters(run_options), "frame_id": frame_id}


def live_reports(runs, options: CheckOptions, *, node_name: str | None = None, context=None,
                 timeout: float = 120.0, on_run=None) -> list[list[dict]]:
    """The reports a live rbe_node returns for each run's state (message dicts)."""
    own_context = context is None
    if own_context:
        context = rclpy.Context()
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    process = None
    client = None
    restore = None
    try:
        if node_name is None:
            node_name = f"rbe_replay_{os.getpid()}"
            process = NodeProcess.named(node_name, node_parameters(options))

        def alive() -> None:
            if process is not None and process.proc.poll() is not None:
                raise RuntimeError(f"rbe_node exited ({process.proc.returncode}):\n"
                                   f"{process.output()}")

        client = _Client(context, node_name)
        client.wait_ready(60.0 if process is not None else 30.0, alive)
        out = []
        settings = None
        for i, run in enumerate(runs):
            if run.settings is not None and run.settings != settings:
                wanted = settings_parameters(run, options)
                if process is None and restore is None:     # a running node: put it back
                    restore = client.get_parameters(list(wanted), timeout)
                client.set_parameters(wanted, timeout)
                settings = run.settings
            if run.kind == PLAN:
                out.append(client.plan(live_goal(run), timeout))
            else:
                state = dict_to_message(run.state, client.publishers[run.kind][1])
                if run.kind == STATE and run.state.get("sequence"):
                    out.append(client.check_sequence(state, timeout))
                else:
                    answer = client.check_whole(state, timeout, run.kind)
                    out.append(answer if run.kind == STATE or run.reports else [])
            alive()
            if on_run is not None:
                on_run(i, run)
        return out
    finally:
        if client is not None:
            try:
                if restore is not None:
                    client.set_parameters(restore, timeout)
            finally:
                client.close()
        if process is not None:
            process.stop()
        if own_context:
            rclpy.try_shutdown(context=context)


def live_recheck(node_name: str | None = None, context=None, timeout: float = 120.0):
    """A ``recheck`` for :func:`rbe_ros.io.replay.replay_bag`: through a live rbe_node
    (started here, or the running one named ``node_name``; see :func:`live_reports`)."""
    def recheck(runs, options: CheckOptions, on_run=None) -> list[list[dict]]:
        return live_reports(runs, options, node_name=node_name, context=context,
                            timeout=timeout, on_run=on_run)
    return recheck


__all__ = ["NodeProcess", "live_recheck", "live_reports", "node_parameters",
           "settings_parameters"]
